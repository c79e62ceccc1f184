"""Acoustic channel core: round-robin OWTT ranging with loss and multipath.

Timing model (sblsim's documented choice). Each communication step of the
channel is one round-robin slot of length T: the slot ending at ``t_k = k T``
(k = 1, 2, ...) is transmitted by beacon ``((k - 1) mod n) + 1`` at epoch
``t_k`` from its true position ``b_i(t_k)``. The packet reaches the diver at
``t_k + τ``; the one-way travel time τ solves
``τ = ‖p(t_k) + v(t_k) τ − b_i(t_k)‖ / c̄`` (three fixed-point iterations;
c̄ the harmonic-mean sound speed along the path), so **the true range refers
to the target's position at reception**. The receiver, synchronized to GPS
time at power-on, measures ``τ_m = τ + δ (t_k + τ)`` with clock drift δ and
turns it into a range with the assumed sound speed,
``r = c_assumed τ_m + σ_r w + e_mp``, where ``e_mp > 0`` (exponential, mean
``outlier_excess``) is added with probability ``p_out`` (reflected path) and
the packet is lost with probability ``p_loss``. The packet carries the
beacon id, ``t_k`` and the beacon's broadcast position.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4
(round-robin OWTT, range noise, packet loss). Eustice, Singh, Leonard,
"Synchronous-clock one-way-travel-time acoustic navigation for underwater
vehicles", J. Field Robotics 28(1), 2011 (OWTT with synchronized clocks).
"""

from __future__ import annotations

import numpy as np

from models.core import SEED_PARAMETERS, ComponentCore, Variable
from models.acoustics.sound_speed import load_profile
from models.platform.core import AXES, beacon_names, beacon_variables

_CHANNEL_UNIFORM, _RANGE_NOISE = range(2)
#: The packet a slot delivers: outputs of the channel, inputs of every receiver.
PACKET: tuple[Variable, ...] = (
    Variable("packet_seq", "output", "Integer", 0, description="Slot counter k (0: no packet yet)"),
    Variable("beacon_id", "output", "Integer", 0, description="Transmitting beacon (1-based; 0: none)"),
    Variable("packet_valid", "output", "Boolean", False, description="Packet received (not lost)"),
    Variable("tx_time", "output", "Real", 0.0, "s", "Transmit epoch t_k of the packet"),
    Variable("range", "output", "Real", 0.0, "m", "Measured OWTT range (NaN when lost)"),
    Variable("beacon_x", "output", "Real", 0.0, "m", "Broadcast beacon position in the packet, North"),
    Variable("beacon_y", "output", "Real", 0.0, "m", "Broadcast beacon position in the packet, East"),
    Variable("beacon_z", "output", "Real", 0.0, "m", "Broadcast beacon position in the packet, Down"),
)
TARGET_INPUTS = ("target_x", "target_y", "target_z", "target_vx", "target_vy", "target_vz")


class AcousticsCore(ComponentCore):
    """Round-robin one-way-travel-time acoustic channel.

    Attributes
    ----------
    profile : SoundSpeedProfile
        True sound-speed profile.
    seq : int
        Number of slots emitted so far.
    """

    name = "acoustics"
    component_index = 1
    batched_parameters = frozenset({"cell", "sound_speed_assumed", "clock_drift_ppm", "sigma_range", "loss_pct",
                                    "outlier_pct", "outlier_excess"})

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        params = (
            Variable("sound_speed_assumed", "parameter", "Real", 1500.0, "m/s",
                     "Sound speed the receiver assumes to turn travel time into range", min=1300.0, max=1700.0),
            Variable("sound_speed_true", "parameter", "Real", 1500.0, "m/s",
                     "True sound speed when the profile is constant", min=1300.0, max=1700.0),
            Variable("sound_speed_profile", "parameter", "String", "constant",
                     description="True sound speed: constant, teos10, ctd:NAME or a CSV cast path"),
            Variable("temperature", "parameter", "Real", 15.0, "degC", "Water temperature for teos10",
                     min=-2.0, max=40.0),
            Variable("salinity", "parameter", "Real", 35.0, "g/kg", "Salinity for teos10", min=0.0, max=42.0),
            Variable("clock_drift_ppm", "parameter", "Real", 0.0, "ppm",
                     "Receiver clock drift after power-on synchronization", min=-1000.0, max=1000.0),
            Variable("sigma_range", "parameter", "Real", 0.1, "m", "Range noise standard deviation",
                     min=0.0, max=1000.0),
            Variable("loss_pct", "parameter", "Real", 0.0, "%", "Packet-loss probability", min=0.0, max=100.0),
            Variable("outlier_pct", "parameter", "Real", 0.0, "%", "Multipath-outlier probability",
                     min=0.0, max=100.0),
            Variable("outlier_excess", "parameter", "Real", 2.0, "m",
                     "Mean excess length of a multipath outlier (exponential)", min=0.0, max=1e4),
        )
        inputs = beacon_variables(n_beacons, "input") + tuple(
            Variable(n, "input", "Real", 0.0, unit, f"True target {what}, {axis} [NED]")
            for n, unit, what, axis in zip(
                TARGET_INPUTS, ("m",) * 3 + ("m/s",) * 3, ("position",) * 3 + ("velocity",) * 3,
                ("North", "East", "Down") * 2))
        outputs = PACKET + (
            Variable("travel_time", "output", "Real", 0.0, "s", "True one-way travel time"),
            Variable("range_true", "output", "Real", 0.0, "m",
                     "True distance from beacon at transmit to target at reception"),
            Variable("outlier", "output", "Boolean", False, description="Range lengthened by multipath"),
        )
        return params + SEED_PARAMETERS + inputs + outputs

    def __init__(self, params, replicates=None, n_beacons: int = 4) -> None:
        super().__init__(params, replicates, n_beacons)
        p = self.params
        self.profile = load_profile(p["sound_speed_profile"], p["sound_speed_true"], p["temperature"], p["salinity"])
        true, sent = beacon_names(self.n_beacons, "true"), beacon_names(self.n_beacons, "broadcast")
        # per beacon: names of its true and broadcast (x, y, z) inputs
        self._beacon_inputs = [(true[3 * i:3 * i + 3], sent[3 * i:3 * i + 3]) for i in range(self.n_beacons)]

    def _initialize(self, t0: float) -> None:
        self.rng = self.streams()
        self.seq = 0
        nan = np.full(self.batch, np.nan)
        zero = np.zeros(self.batch, dtype=np.int64)
        false = np.zeros(self.batch, dtype=bool)
        self.outputs = dict(packet_seq=zero, beacon_id=zero, packet_valid=false, tx_time=np.full(self.batch, t0),
                            range=nan, beacon_x=nan, beacon_y=nan, beacon_z=nan, travel_time=nan,
                            range_true=nan, outlier=false)

    def travel_time(self, beacon: np.ndarray, position: np.ndarray, velocity: np.ndarray,
                    iterations: int = 3) -> tuple[np.ndarray, np.ndarray]:
        """True OWTT from a beacon to a moving target.

        Parameters
        ----------
        beacon : ndarray, shape (B, 3)
            True beacon position at transmit [m].
        position, velocity : ndarray, shape (B, 3)
            Target position [m] and velocity [m/s] at transmit.

        Returns
        -------
        tau : ndarray, shape (B,)
            Travel time [s].
        distance : ndarray, shape (B,)
            Path length: beacon at transmit to target at reception [m].
        """
        tau = np.zeros(position.shape[0])
        for _ in range(iterations):
            receive = position + velocity * tau[:, None]
            distance = np.linalg.norm(receive - beacon, axis=-1)
            tau = distance / self.profile.harmonic_mean(beacon[:, 2], receive[:, 2])
        receive = position + velocity * tau[:, None]
        distance = np.linalg.norm(receive - beacon, axis=-1)
        return distance / self.profile.harmonic_mean(beacon[:, 2], receive[:, 2]), distance

    def _step(self, t: float, dt: float) -> None:
        p, u = self.params, self.inputs
        t_tx = t + dt
        self.seq += 1
        i = (self.seq - 1) % self.n_beacons
        true_names, sent_names = self._beacon_inputs[i]
        beacon = np.column_stack([u[n] for n in true_names]).astype(float)
        position = np.column_stack([u[n] for n in TARGET_INPUTS[:3]]).astype(float)
        velocity = np.column_stack([u[n] for n in TARGET_INPUTS[3:]]).astype(float)
        tau, distance = self.travel_time(beacon, position, velocity)

        draws = self.rng.draw(_CHANNEL_UNIFORM, "uniform", 3)
        noise = self.rng.draw(_RANGE_NOISE, "normal", 1)[:, 0]
        valid = draws[:, 0] >= p["loss_pct"] / 100.0
        outlier = draws[:, 1] < p["outlier_pct"] / 100.0
        excess = np.where(outlier, -p["outlier_excess"] * np.log1p(-draws[:, 2]), 0.0)
        measured_tau = tau + p["clock_drift_ppm"] * 1e-6 * (t_tx + tau)
        rng = p["sound_speed_assumed"] * measured_tau + p["sigma_range"] * noise + excess

        nan = np.full(self.batch, np.nan)
        self.outputs = dict(
            packet_seq=np.full(self.batch, self.seq, dtype=np.int64),
            beacon_id=np.full(self.batch, i + 1, dtype=np.int64),
            packet_valid=valid,
            tx_time=np.full(self.batch, t_tx),
            range=np.where(valid, rng, nan),
            **{f"beacon_{a}": np.where(valid, np.asarray(u[n], float), nan) for a, n in zip(AXES, sent_names)},
            travel_time=tau,
            range_true=distance,
            outlier=outlier & valid,
        )
