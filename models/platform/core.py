"""Platform: the floating SBL base with its beacons, wave motion, GPS and IMU; an LBL seafloor array; a USBL
transceiver.

True beacon positions ``b_i(t) = p(t) + R(roll, pitch, yaw) a_i`` at any
time; the broadcast ones are *sampled* every ``sample_period`` T_s at
``t_k = t0 + k T_s`` from the GPS position and IMU attitude,
``b̃_i = p̃_k + R(roll~_k, pitch~_k, yaw~_k) a_i``, and held until the next
sample, so they do not depend on how a host steps the component. The platform
is moored at the NED origin and heaves with the waves. GPS error is white or
first-order Gauss-Markov with correlation time τ (exact discretization
``e_k+1 = e^(-T_s/τ) e_k + σ sqrt(1 - e^(-2T_s/τ)) w_k``, stationary start);
IMU error is white with standard deviation σ_IMU plus a constant bias and a
gyro-bias drift ``ω_b t``.

Errors fixed for a run (drawn once, at initialization, from streams of their
own): each beacon's true body offset is ``a_i + δ_i``, ``δ_i ~ N(0, σ_inst² I)``
(transducer installation error), while the platform broadcasts the nominal
``a_i``; the IMU measures each angle θ as ``(1 + s) θ + m + bias + noise``
with a per-axis scale-factor error ``s ~ N(0, σ_s²)`` and a per-axis
misalignment ``m ~ N(0, σ_m²)``.

Systems (``system``, docs/model.md "Systems"; each is an object of
:mod:`sblsim.models.systems`, which this program asks where the transducers
are). ``sbl``: the above. ``lbl``: the transponders stand on the seafloor,
transponder i at NED ``(a_ix, a_iy, seafloor_depth)`` (a custom layout's
offsets are the NED positions themselves); they do not move, need no GPS or
IMU, and the positions the packets carry are the *surveyed* ones,
``b_i + s_i``, ``s_i ~ N(0, σ_survey² I)`` drawn once per run (a bias, not a
noise). ``usbl``: one transceiver (the interface of one beacon) at the lever
arm ``(0, 0, transducer_depth)`` below the GPS antenna whatever ``baseline``
(a custom layout's one offset instead), whose array is mounted with a
misalignment ``μ ~ N(0, σ_μ² I)`` per axis, drawn once per run: the array's
attitude is the platform's plus μ (``array_*`` outputs), while the surface
converts the array's angles with the IMU's measured attitude (``imu_*``
outputs).

References
----------
Cario et al., "Accurate Localization in Acoustic Underwater Localization
Systems", Sensors 21(3):762, 2021, doi:10.3390/s21030762, Sections 3-4
(platform model, GPS and IMU errors, broadcast beacon positions); Figure 4 and
Table 1 (the error sources, among them installation, IMU scale factor and
misalignment, and the IMU grades).
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import casadi as ca
import numpy as np

from sblsim.models.component import Component
from sblsim.models.declarations import SEED_PARAMETERS, ModelError, Variable, signal_range
from sblsim.models.expressions import sample_due
from sblsim.models.platform.geometry import beacon_positions, parse_offsets, rotation_ned
from sblsim.models.platform.waves import wave_motion
from sblsim.models.program import ProgramBuilder, Stream
from sblsim.models.systems import SYSTEMS, interface_system, interface_systems
from sblsim.models.table_text import format_table

AXES = ("x", "y", "z")
#: Beacon layouts: the paper's cross of 4, any given offsets, N equally spaced on a circle (appended: the
#: FMUs and the local engine encode a choice by its index).
LAYOUTS = ("cross", "custom", "circle")
#: Allowed numbers of beacons (``platform.beacons``).
MIN_BEACONS, MAX_BEACONS = 3, 16
#: The largest offset of a custom layout's transducer from the platform's reference [m]: an LBL field's
#: transponders stand up to 100 km from the origin.
MAX_OFFSET = 1e5
GPS_MODELS = ("white", "gauss-markov")

# Stream purposes (sblsim.models.philox, "Randomness").
_PHASES, _GPS, _IMU, _INSTALLATION, _IMU_SCALE, _IMU_MISALIGNMENT, _SURVEY, _USBL_MISALIGNMENT = range(8)


def attitude_variables(prefix: str, causality: str, what: str, discrete: bool) -> tuple[Variable, ...]:
    """Roll, pitch and yaw [rad] named ``<prefix>_roll`` ... (the USBL array's and the IMU's attitude)."""
    return tuple(Variable(f"{prefix}_{a}", causality, "Real", 0.0, "rad", f"{what} {a}", discrete=discrete,
                          min=-10.0, max=10.0) for a in ("roll", "pitch", "yaw"))


#: The USBL attitudes the platform outputs and the channel reads: the array's true one, the IMU's measured one.
USBL_ATTITUDES = (("array", "True attitude of the USBL array (platform attitude plus mounting misalignment),",
                   False),
                  ("imu", "IMU-measured platform attitude as sampled,", True))


def beacon_names(n_beacons: int, kind: str) -> list[str]:
    """Variable names of the beacon positions, beacon-major: ``beacon1_x, beacon1_y, ...``.

    ``kind`` is ``'true'`` for the true positions or ``'broadcast'`` for the
    positions computed from GPS and IMU.
    """
    infix = "_true" if kind == "true" else ""
    return [f"beacon{i}{infix}_{a}" for i in range(1, n_beacons + 1) for a in AXES]


def beacon_variables(n_beacons: int, causality: str) -> tuple[Variable, ...]:
    """Declarations of the true and broadcast beacon positions (outputs of the
    platform, inputs of the channel), in the order of :func:`beacon_names`.
    The true positions are continuous; the broadcast ones are sampled (discrete)."""
    return tuple(
        Variable(f"beacon{i}{infix}_{a}", causality, "Real", 0.0, "m",
                 f"{label} position of beacon {i}, {axis} [NED]", discrete=(infix == ""), **signal_range("position"))
        for infix, label in (("_true", "True"), ("", "Broadcast (GPS and IMU)"))
        for i in range(1, n_beacons + 1) for a, axis in zip(AXES, ("North", "East", "Down")))


class Platform(Component):
    """SBL platform: beacons (cross, circle or custom), Beaufort wave motion, GPS, IMU and broadcast positions."""

    name = "platform"
    component_index = 0

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        offsets = tuple(
            Variable(f"beacon{i}_offset_{a}", "parameter", "Real", 0.0, "m",
                     f"Custom layout: body-frame offset of beacon {i}, {a}", min=-MAX_OFFSET, max=MAX_OFFSET,
                     scope="fmu")
            for i in range(1, n_beacons + 1) for a in AXES)
        params = (
            Variable("layout", "parameter", "String", "cross", description="Beacon layout", choices=LAYOUTS),
            Variable("beacons", "parameter", "Integer", 4, min=MIN_BEACONS, max=MAX_BEACONS, scope="config",
                     description="Number of beacons N (circle; 4 for the cross, the offsets' count for custom)"),
            Variable("baseline", "parameter", "Real", 1.0, "m", "Support-arm length L of each beacon",
                     min=0.0, max=1000.0, min_exclusive=True),
            Variable("transducer_depth", "parameter", "Real", 1.0, "m",
                     "Transducer depth h below the platform reference", min=0.0, max=1000.0),
            Variable("beacon_offsets", "parameter", "String", "",
                     description="Custom layout body offsets 'x y z; ...' [m] (layout = custom)", scope="config"),
        ) + offsets + (
            Variable("heading_deg", "parameter", "Real", 0.0, "deg", "Mean platform heading",
                     min=-180.0, max=180.0),
            Variable("beaufort", "parameter", "Integer", 2, description="Sea state on the Beaufort scale",
                     min=0, max=8),
            Variable("hull_length", "parameter", "Real", 2.0, "m", "Platform hull length",
                     min=0.0, max=1000.0, min_exclusive=True),
            Variable("gps_sigma", "parameter", "Real", 0.1, "m", "GPS error standard deviation per axis",
                     min=0.0, max=1000.0),
            Variable("gps_model", "parameter", "String", "white", description="GPS error model",
                     choices=GPS_MODELS),
            Variable("gps_tau", "parameter", "Real", 60.0, "s", "GPS Gauss-Markov correlation time",
                     min=0.0, max=1e6, min_exclusive=True),
            Variable("imu_sigma_deg", "parameter", "Real", 1.0, "deg",
                     "IMU roll/pitch/yaw error standard deviation", min=0.0, max=180.0),
            Variable("imu_bias_deg", "parameter", "Real", 0.0, "deg", "IMU constant attitude bias (all axes)",
                     min=-180.0, max=180.0),
            Variable("imu_gyro_bias", "parameter", "Real", 0.0, "rad/s",
                     "Gyro bias: attitude error drift rate (all axes)", min=-1.0, max=1.0),
            Variable("installation_sigma", "parameter", "Real", 0.0, "m",
                     "Transducer installation error: std of each beacon's offset error per axis, fixed per run",
                     min=0.0, max=10.0),
            Variable("imu_scale_factor_ppm", "parameter", "Real", 0.0, "ppm",
                     "IMU scale-factor error std per axis, fixed per run", min=0.0, max=1e5),
            Variable("imu_misalignment_deg", "parameter", "Real", 0.0, "deg",
                     "IMU axis misalignment std per axis, fixed per run", min=0.0, max=10.0),
            Variable("sample_period", "parameter", "Real", 0.1, "s",
                     "GPS and IMU sampling period T_s (the sampling time T)", min=0.001, max=60.0, scope="fmu"),
        )
        outputs = beacon_variables(n_beacons, "output")
        attitude = tuple(Variable(a, "output", "Real", 0.0, "rad", f"True platform {a}")
                         for a in ("roll", "pitch", "yaw"))
        gps = tuple(Variable(f"gps_{a}", "output", "Real", 0.0, "m", f"GPS-measured platform {a}", discrete=True)
                    for a in AXES)
        # declared after the SBL ones, so that their value references stay what they were
        systems = (
            Variable("system", "parameter", "String", interface_system(n_beacons).name,
                     description="Positioning system", choices=tuple(SYSTEMS)),
            Variable("seafloor_depth", "parameter", "Real", 50.0, "m", "LBL: depth of the seafloor transponders",
                     min=0.0, max=12000.0, min_exclusive=True),
            Variable("survey_sigma", "parameter", "Real", 0.0, "m",
                     "LBL: survey error std of each transponder's position per axis, fixed per run",
                     min=0.0, max=100.0),
            Variable("usbl_angle_sigma_deg", "parameter", "Real", 0.5, "deg",
                     "USBL: direction-of-arrival error std on the array's axis (grows off axis)",
                     min=0.0, max=45.0, scope="config"),
            Variable("usbl_misalignment_deg", "parameter", "Real", 0.0, "deg",
                     "USBL: array mounting misalignment std per axis against the IMU, fixed per run",
                     min=0.0, max=10.0),
        )
        usbl = tuple(v for prefix, what, discrete in USBL_ATTITUDES
                     for v in attitude_variables(prefix, "output", what, discrete))
        return params + SEED_PARAMETERS + outputs + attitude + gps + systems + usbl

    @classmethod
    def fmu_parameters(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """FMU parameters of a configuration section: a custom layout's text becomes the offset parameters.

        Raises
        ------
        ModelError
            If a custom layout's offsets are malformed or their number differs from ``n_beacons``.
        """
        out = super().fmu_parameters(values, n_beacons)
        if values.get("layout") == "custom":
            offsets = parse_offsets(values.get("beacon_offsets", ""))
            if offsets.shape[0] != n_beacons:
                raise ModelError(f"platform.beacon_offsets: {offsets.shape[0]} beacons given, "
                                 f"the interface has {n_beacons}")
            out.update({f"beacon{i + 1}_offset_{a}": float(offsets[i, k])
                        for i in range(n_beacons) for k, a in enumerate(AXES)})
        return out

    @classmethod
    def config_values(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """Configuration keys from FMU parameters: a custom layout's offsets become the ``beacon_offsets`` text."""
        out = super().config_values(values, n_beacons)
        if interface_system(n_beacons).interface_beacons is None:  # a fixed interface is not a count of beacons
            out["beacons"] = int(n_beacons)
        if out.get("layout") == "custom":
            out["beacon_offsets"] = format_table(np.array(
                [[float(values.get(f"beacon{i}_offset_{a}", 0.0)) for a in AXES] for i in range(1, n_beacons + 1)]))
        return out

    @classmethod
    def build(cls, n_beacons: int):
        n = n_beacons
        b = ProgramBuilder(cls, n, states=[("t0", 1), ("k", 1), ("phase_sin", 4), ("phase_cos", 4),
                                            ("gps_error", 3), ("gps", 3), ("broadcast", 3 * n),
                                            ("installed", 3 * n), ("imu_scale", 3), ("imu_misalignment", 3),
                                            ("survey", 3 * n), ("usbl_misalignment", 3), ("imu", 3)],
                           derived=[("offsets", 3 * n), ("motion", 4), ("seafloor", 3 * n)])
        # the systems of this interface: the first places the transducers on the platform, the others (LBL) may
        # place them elsewhere where the ``system`` parameter names them
        own, systems = interface_system(n), interface_systems(n)

        def prepare(p):
            offsets = own.body_offsets(p, n, LAYOUTS)
            # fixed arrays: the layout's points on the seafloor, a custom layout's offsets as NED positions
            seafloor = [ca.if_else(p["layout"] == LAYOUTS.index("custom"), a, ca.vertcat(a[0], a[1],
                                                                                          p["seafloor_depth"]))
                        for a in offsets]
            return {"offsets": ca.vertcat(*offsets), "motion": ca.vertcat(*wave_motion(p["beaufort"],
                                                                                      p["hull_length"])),
                    "seafloor": ca.vertcat(*seafloor)}

        def attitude(p, d, x, t):
            """True roll, pitch, yaw [rad] and platform depth (heave) [m] at ``t``."""
            tilt, yaw_amp, heave, freq = (d["motion"][k] for k in range(4))
            w = 2.0 * math.pi * freq * t
            full, half = (ca.sin(w), ca.cos(w)), (ca.sin(0.5 * w), ca.cos(0.5 * w))

            def wave(angle, k):  # sin(angle + φ_k) = sin(angle) cos φ_k + cos(angle) sin φ_k
                return angle[0] * x["phase_cos"][k] + angle[1] * x["phase_sin"][k]

            roll = tilt * wave(full, 0)
            pitch = tilt * wave(full, 1)
            yaw = p["heading_deg"] * (math.pi / 180.0) + yaw_amp * wave(half, 2)
            return roll, pitch, yaw, -heave * wave(full, 3)

        def offsets(d):
            return [d["offsets"][3 * i:3 * i + 3] for i in range(n)]

        def sample(p, d, x, gps_error, imu_noise, t_k, systems=systems):
            """GPS position and broadcast beacon positions sampled at ``t_k`` (``x``: the phases and the
            IMU's scale-factor and misalignment errors) where ``p["system"]`` is one of ``systems``."""
            roll, pitch, yaw, depth = attitude(p, d, x, t_k)
            gps = ca.vertcat(0.0, 0.0, depth) + gps_error
            bias = p["imu_bias_deg"] * (math.pi / 180.0) + p["imu_gyro_bias"] * t_k
            sigma = p["imu_sigma_deg"] * (math.pi / 180.0)
            scale, misalignment = x["imu_scale"], x["imu_misalignment"]
            imu = [(1.0 + scale[k]) * a + bias + sigma * imu_noise[k] + misalignment[k]
                   for k, a in enumerate((roll, pitch, yaw))]
            broadcast = ca.vertcat(*beacon_positions(gps, rotation_ned(*imu), offsets(d)))
            for system in systems:  # LBL: the surveyed transponder positions
                broadcast = system.placed_broadcast(p, d, x, broadcast)
            return {"gps": gps, "broadcast": broadcast, "imu": ca.vertcat(*imu)}

        def init(p, d, w, t0):
            phases = 2.0 * math.pi * w[_PHASES]
            wave_phases = {"phase_sin": ca.sin(phases), "phase_cos": ca.cos(phases)}
            gps_error = p["gps_sigma"] * w[_GPS]  # stationary start of either model
            # the body offsets as installed: the layout's plus the installation error (per run: zero when σ = 0)
            fixed = {"installed": d["offsets"] + p["installation_sigma"] * w[_INSTALLATION],
                     "imu_scale": p["imu_scale_factor_ppm"] * 1e-6 * w[_IMU_SCALE],
                     "imu_misalignment": p["imu_misalignment_deg"] * (math.pi / 180.0) * w[_IMU_MISALIGNMENT],
                     "survey": p["survey_sigma"] * w[_SURVEY],
                     "usbl_misalignment": p["usbl_misalignment_deg"] * (math.pi / 180.0) * w[_USBL_MISALIGNMENT]}
            return {"t0": t0, "k": 0, **wave_phases, "gps_error": gps_error, **fixed,
                    **sample(p, d, {**wave_phases, **fixed}, gps_error, w[_IMU], t0)}

        def due(x, u, p, d, t, h):
            return sample_due(x["k"], x["t0"], p["sample_period"], t, h)

        def take_sample(systems):
            """The sample event's handler in the runs of ``systems``."""
            def handler(x, u, p, d, w, t, h):
                k = x["k"] + 1
                t_k = x["t0"] + k * p["sample_period"]
                phi = ca.exp(-p["sample_period"] / p["gps_tau"])
                markov = phi * x["gps_error"] + p["gps_sigma"] * ca.sqrt(1.0 - phi * phi) * w[_GPS]
                gps_error = ca.if_else(p["gps_model"] == GPS_MODELS.index("white"), p["gps_sigma"] * w[_GPS],
                                       markov)
                return {"k": k, "gps_error": gps_error, **sample(p, d, x, gps_error, w[_IMU], t_k, systems)}
            return handler

        def output(x, p, d, t):
            roll, pitch, yaw, depth = attitude(p, d, x, t)
            installed = [x["installed"][3 * i:3 * i + 3] for i in range(n)]
            true = ca.vertcat(*beacon_positions(ca.vertcat(0.0, 0.0, depth), rotation_ned(roll, pitch, yaw),
                                                installed))
            for system in systems:  # LBL: the transponders on the seafloor
                true = system.placed_true(p, d, true)
            out = {name: true[k] for k, name in enumerate(beacon_names(n, "true"))}
            out.update({name: x["broadcast"][k] for k, name in enumerate(beacon_names(n, "broadcast"))})
            out.update(roll=roll, pitch=pitch, yaw=yaw)
            out.update({f"gps_{a}": x["gps"][k] for k, a in enumerate(AXES)})
            for k, a in enumerate(("roll", "pitch", "yaw")):
                out[f"array_{a}"] = (roll, pitch, yaw)[k] + x["usbl_misalignment"][k]
                out[f"imu_{a}"] = x["imu"][k]
            return out

        noise = (Stream(_GPS, "normal", 3), Stream(_IMU, "normal", 3))
        # drawn once per run, each from a stream of its own, so that the other streams keep their numbers
        fixed = (Stream(_INSTALLATION, "normal", 3 * n), Stream(_IMU_SCALE, "normal", 3),
                 Stream(_IMU_MISALIGNMENT, "normal", 3), Stream(_SURVEY, "normal", 3 * n),
                 Stream(_USBL_MISALIGNMENT, "normal", 3))
        # a sample event of the runs whose system places no transducer elsewhere (SBL, USBL), which computes no
        # other placement, and one of each system that does (LBL's surveyed positions)
        placing = [s for s in systems if s.places_transducers]
        others = [name for name, s in SYSTEMS.items() if s not in placing]
        events = [b.event("sample", due, take_sample([]), noise, when={"system": others} if placing else None)]
        events += [b.event(f"sample_{s.name}", due, take_sample([s]), noise, when={"system": [s.name]})
                   for s in placing]
        return b.program(b.prepare(prepare), b.init(init, (Stream(_PHASES, "uniform", 4),) + noise + fixed),
                         b.output(output), events=events)


__all__ = ["AXES", "GPS_MODELS", "LAYOUTS", "MAX_BEACONS", "MAX_OFFSET", "MIN_BEACONS", "Platform", "USBL_ATTITUDES",
           "attitude_variables", "beacon_names", "beacon_variables"]
