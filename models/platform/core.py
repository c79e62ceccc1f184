"""Platform core: the floating SBL base with its beacons, wave motion, GPS and IMU.

References
----------
Cario et al., "Accurate Localization in Acoustic Underwater Localization
Systems", Sensors 21(3):762, 2021, doi:10.3390/s21030762, Sections 3-4
(platform model, GPS and IMU errors, broadcast beacon positions).
"""

from __future__ import annotations

import numpy as np

from models.core import SEED_PARAMETERS, ComponentCore, ModelError, Variable
from models.platform.geometry import beacon_positions, cross_offsets, parse_offsets, rotation_ned
from models.platform.waves import wave_motion

AXES = ("x", "y", "z")

# Purposes of the platform's random streams (see models.core.RandomStreams).
_PHASES, _GPS, _IMU, _GPS_INIT = range(4)


def beacon_names(n_beacons: int, kind: str) -> list[str]:
    """Variable names of the beacon positions, beacon-major: ``beacon1_x, beacon1_y, ...``.

    ``kind`` is ``'true'`` for the true positions or ``'broadcast'`` for the
    positions computed from GPS and IMU.
    """
    infix = "_true" if kind == "true" else ""
    return [f"beacon{i}{infix}_{a}" for i in range(1, n_beacons + 1) for a in AXES]


def beacon_variables(n_beacons: int, causality: str) -> tuple[Variable, ...]:
    """Declarations of the true and broadcast beacon positions (outputs of the
    platform, inputs of the channel), in the order of :func:`beacon_names`."""
    return tuple(
        Variable(f"beacon{i}{infix}_{a}", causality, "Real", 0.0, "m",
                 f"{label} position of beacon {i}, {axis} [NED]")
        for infix, label in (("_true", "True"), ("", "Broadcast (GPS and IMU)"))
        for i in range(1, n_beacons + 1) for a, axis in zip(AXES, ("North", "East", "Down")))


def _column(value):
    """A per-replicate parameter as a column (B, 1) for (B, 3) arrays; scalars unchanged."""
    return value[:, None] if isinstance(value, np.ndarray) and value.ndim == 1 else value


class PlatformCore(ComponentCore):
    """SBL platform: beacon cross, Beaufort wave motion, GPS, IMU and broadcast positions.

    True beacon positions ``b_i(t) = p(t) + R(roll, pitch, yaw) a_i``; the
    broadcast ones use the GPS position and IMU attitude,
    ``b̃_i = p̃ + R(roll~, pitch~, yaw~) a_i``. The platform is moored at the
    NED origin and heaves with the waves. GPS error is white or first-order
    Gauss-Markov with correlation time τ (exact discretization
    ``e_k+1 = e^(-Δt/τ) e_k + σ sqrt(1 - e^(-2Δt/τ)) w_k``, stationary start).
    IMU error is white with standard deviation σ_IMU plus a constant bias and
    a gyro-bias drift ``ω_b t``.

    Attributes
    ----------
    offsets : ndarray, shape (n, 3) or (B, n, 3)
        Body-frame beacon offsets [m] (per replicate when the baseline or
        transducer depth differ across the batch).
    phases : ndarray, shape (B, 4)
        Random phases of roll, pitch, yaw and heave [rad].
    gps_error : ndarray, shape (B, 3)
        Current GPS error [m].
    """

    name = "platform"
    component_index = 0
    batched_parameters = frozenset({"cell", "baseline", "transducer_depth", "heading_deg", "gps_sigma", "gps_tau",
                                    "imu_sigma_deg", "imu_bias_deg", "imu_gyro_bias"})

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        params = (
            Variable("layout", "parameter", "String", "cross", description="Beacon layout",
                     choices=("cross", "custom")),
            Variable("baseline", "parameter", "Real", 1.0, "m", "Support-arm length L of each beacon",
                     min=0.0, max=1000.0, min_exclusive=True),
            Variable("transducer_depth", "parameter", "Real", 1.0, "m",
                     "Transducer depth h below the platform reference", min=0.0, max=1000.0),
            Variable("beacon_offsets", "parameter", "String", "",
                     description="Custom layout body offsets 'x y z; ...' [m] (layout = custom)"),
            Variable("heading_deg", "parameter", "Real", 0.0, "deg", "Mean platform heading",
                     min=-180.0, max=180.0),
            Variable("beaufort", "parameter", "Integer", 2, description="Sea state on the Beaufort scale",
                     min=0, max=8),
            Variable("hull_length", "parameter", "Real", 2.0, "m", "Platform hull length",
                     min=0.0, max=1000.0, min_exclusive=True),
            Variable("gps_sigma", "parameter", "Real", 0.1, "m", "GPS error standard deviation per axis",
                     min=0.0, max=1000.0),
            Variable("gps_model", "parameter", "String", "white", description="GPS error model",
                     choices=("white", "gauss-markov")),
            Variable("gps_tau", "parameter", "Real", 60.0, "s", "GPS Gauss-Markov correlation time",
                     min=0.0, max=1e6, min_exclusive=True),
            Variable("imu_sigma_deg", "parameter", "Real", 1.0, "deg",
                     "IMU roll/pitch/yaw error standard deviation", min=0.0, max=180.0),
            Variable("imu_bias_deg", "parameter", "Real", 0.0, "deg", "IMU constant attitude bias (all axes)",
                     min=-180.0, max=180.0),
            Variable("imu_gyro_bias", "parameter", "Real", 0.0, "rad/s",
                     "Gyro bias: attitude error drift rate (all axes)", min=-1.0, max=1.0),
        )
        outputs = beacon_variables(n_beacons, "output")
        attitude = tuple(Variable(a, "output", "Real", 0.0, "rad", f"True platform {a}")
                         for a in ("roll", "pitch", "yaw"))
        gps = tuple(Variable(f"gps_{a}", "output", "Real", 0.0, "m", f"GPS-measured platform {a}")
                    for a in AXES)
        return params + SEED_PARAMETERS + outputs + attitude + gps

    def __init__(self, params, replicates=None, n_beacons: int = 4) -> None:
        super().__init__(params, replicates, n_beacons)
        p = self.params
        if p["layout"] == "cross":
            self.offsets = cross_offsets(p["baseline"], p["transducer_depth"], self.n_beacons)
        else:
            self.offsets = parse_offsets(p["beacon_offsets"])
            if self.offsets.shape[0] != self.n_beacons:
                raise ModelError(f"platform.beacon_offsets: {self.offsets.shape[0]} beacons given, "
                                 f"the interface has {self.n_beacons}")
        self.motion = wave_motion(p["beaufort"], p["hull_length"])

    def _initialize(self, t0: float) -> None:
        self.rng = self.streams()
        self.phases = 2.0 * np.pi * self.rng.draw(_PHASES, "uniform", 4)
        self.gps_error = _column(self.params["gps_sigma"]) * self.rng.draw(_GPS_INIT, "normal", 3)
        self._outputs(t0, None)

    def _step(self, t: float, dt: float) -> None:
        self._outputs(t + dt, dt)

    def attitude(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """True roll, pitch, yaw [rad] and heave-induced depth of the reference [m], each (B,)."""
        m, ph = self.motion, self.phases
        w = 2.0 * np.pi * m.frequency * t
        roll = m.tilt_amplitude * np.sin(w + ph[:, 0])
        pitch = m.tilt_amplitude * np.sin(w + ph[:, 1])
        yaw = np.radians(self.params["heading_deg"]) + m.yaw_amplitude * np.sin(0.5 * w + ph[:, 2])
        depth = -m.heave_amplitude * np.sin(w + ph[:, 3])
        return roll, pitch, yaw, depth

    def _outputs(self, t: float, dt: float | None) -> None:
        p = self.params
        roll, pitch, yaw, depth = self.attitude(t)
        position = np.zeros((self.batch, 3))
        position[:, 2] = depth
        true = beacon_positions(position, rotation_ned(roll, pitch, yaw), self.offsets)

        white = self.rng.draw(_GPS, "normal", 3)
        sigma = _column(p["gps_sigma"])
        if p["gps_model"] == "white":
            self.gps_error = sigma * white
        elif dt is not None:
            phi = np.exp(-dt / _column(p["gps_tau"]))
            self.gps_error = phi * self.gps_error + sigma * np.sqrt(1.0 - phi * phi) * white
        gps = position + self.gps_error

        bias = _column(np.radians(p["imu_bias_deg"]) + p["imu_gyro_bias"] * t)
        imu = (np.stack([roll, pitch, yaw], axis=-1) + bias
               + _column(np.radians(p["imu_sigma_deg"])) * self.rng.draw(_IMU, "normal", 3))
        broadcast = beacon_positions(gps, rotation_ned(imu[:, 0], imu[:, 1], imu[:, 2]), self.offsets)

        out = {}
        for kind, values in (("true", true), ("broadcast", broadcast)):
            flat = values.reshape(self.batch, -1)
            out.update({n: flat[:, k] for k, n in enumerate(beacon_names(self.n_beacons, kind))})
        out.update(roll=roll, pitch=pitch, yaw=yaw)
        out.update({f"gps_{a}": gps[:, k] for k, a in enumerate(AXES)})
        self.outputs = out
