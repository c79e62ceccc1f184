"""Positioning systems: one object per system, one module each, listed by :data:`SYSTEMS`.

A system owns what makes it that system: where its transducers are and how
they move (:meth:`System.offsets`, :meth:`System.lever_arms`, the platform
program's :meth:`System.body_offsets`), which ranging it allows
(:attr:`System.ranging`), what one packet measures (its measurement model,
:mod:`sblsim.models.receiver.measurement`) and the receivers' update with it,
the Fisher information of one cycle (:meth:`System.horizontal_std`, the
accuracy map) and its PCRB, where ``sblsim compare`` starts it
(:attr:`System.compare_defaults`), its time-series and log columns and its
words. Everything outside the system modules asks the object; nothing else
names a system.

* :mod:`~sblsim.models.systems.sbl`: short baseline, beacons on the platform;
* :mod:`~sblsim.models.systems.lbl`: long baseline, surveyed seafloor transponders;
* :mod:`~sblsim.models.systems.usbl`: ultra-short baseline, one transceiver measuring range and direction.

This module holds only the base class and the registry, and imports no model:
the components' programs ask the registry (:func:`interface_system`) when they
are built, and ``sblsim.models`` imports the system modules, which register
themselves (:func:`register`). Adding a system is its module (a
:class:`System` subclass, registered), its test and its doc page
(docs/systems.md).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np

from sblsim.models.declarations import ModelError

#: The smallest direction-of-arrival std [deg] the receivers take (their ``sigma_angle_deg``'s minimum): the ties
#: and the bound floor ``platform.usbl_angle_sigma_deg`` at it (:meth:`System.angle_sigma_deg`).
MIN_ANGLE_SIGMA_DEG = 1e-3
#: The smallest range and depth std [m] the receivers take in R (``sigma_range``'s and ``sigma_depth``'s minimum):
#: below it R no longer regularizes the update.
MIN_R_SIGMA = 1e-3

#: The registry: ``platform.system`` value -> system, in the order of :attr:`System.code` (the platform's
#: ``system`` parameter is the index of its value in this order: the FMUs and the local engine encode it so).
SYSTEMS: dict[str, System] = {}


class System:
    """A positioning system (base class; a subclass per system, registered with :func:`register`).

    Attributes
    ----------
    name : str
        The ``platform.system`` value and the word of the command line.
    code : int
        The index of ``name`` in the platform's ``system`` choice (the FMU parameter's encoding), unique.
    title : str
        The system's name in words (docs, help).
    words : str
        What :attr:`compare_defaults` give, in words (``sblsim compare`` help, tables, figures).
    compare_defaults : tuple of str
        ``--set`` overrides applied over the scenario when systems are compared, before the user's.
    marker : str
        What the map calls its transducers ("beacons", "transponders", "transceiver").
    interface_beacons : int or None
        The size of the components' interface (the number of beacon positions the platform broadcasts);
        None: the layout's count (``platform.beacons``).
    ranging : tuple of str
        The ``acoustics.ranging`` values the system allows; the first is forced when only one is allowed.
    measures_direction : bool
        A packet carries a direction of arrival (the channel's azimuth and elevation outputs, the
        receivers' inputs, the platform's array attitude).
    takes_ranges : bool
        A packet is one range, which each receiver takes with its own update (its ``correct``); else the
        receivers take the packet through :meth:`receiver_update` and the fix is :meth:`packet_fix`.
    timeseries_columns : dict
        Time-series columns the system adds: name -> recorded ``component.variable``.
    log_columns : dict
        Columns a replay log of the system adds: log column -> time-series column.
    places_transducers : bool
        The transducers stand elsewhere than on the platform (:meth:`placed_true`, :meth:`placed_broadcast`):
        the platform program samples the broadcast positions of the system's runs with an event of their own.
    bound_fixed, bound_steps : tuple of str
        The per-run and per-step inputs of the system's own compiled PCRB (:meth:`bound_function`); empty
        for a system whose bound is the metrics pass's range bound.
    bound_columns : dict
        The per-step inputs of the bound that the record gives beyond the truth and the packet's common columns:
        name -> recorded ``component.variable`` (USBL: the attitude the packet's direction was turned with),
        recorded whatever time-series columns the system shows.
    fix_packets : int
        The packets of one cycle a fix needs (an availability map's "probability of a fix"): three ranges
        (with the depth, the fix of two is ambiguous), or one packet of range and direction.
    design_layout : str
        How ``sblsim design`` places the transducers: ``seafloor`` (each one in the seafloor region, their count
        and places searched), ``platform`` (on a circle on the platform, its arm searched) or empty (one
        transceiver where the platform is, nothing to place).
    design_grades : tuple of str
        The kinds of hardware grade that change the system's accuracy (what a design chooses among for it:
        ``gps``, ``imu``, ``usbl_head``, ``ranging``).
    designed : bool
        ``sblsim design`` may propose the system (its search evaluates the layout information of ranges whose
        emission is known: an inverted LBL is not among its candidates).
    """

    name: ClassVar[str] = ""
    code: ClassVar[int] = -1
    title: ClassVar[str] = ""
    words: ClassVar[str] = ""
    compare_defaults: ClassVar[tuple[str, ...]] = ()
    marker: ClassVar[str] = "beacons"
    interface_beacons: ClassVar[int | None] = None
    ranging: ClassVar[tuple[str, ...]] = ("owtt", "twtt")
    measures_direction: ClassVar[bool] = False
    takes_ranges: ClassVar[bool] = True
    timeseries_columns: ClassVar[dict[str, str]] = {}
    log_columns: ClassVar[dict[str, str]] = {}
    places_transducers: ClassVar[bool] = False
    bound_fixed: ClassVar[tuple[str, ...]] = ()
    bound_steps: ClassVar[tuple[str, ...]] = ()
    bound_columns: ClassVar[dict[str, str]] = {}
    fix_packets: ClassVar[int] = 3
    design_layout: ClassVar[str] = ""
    design_grades: ClassVar[tuple[str, ...]] = ()
    designed: ClassVar[bool] = True

    def __repr__(self) -> str:
        return f"<positioning system {self.name}>"

    # ---- geometry (numbers, from a resolved ``[platform]`` section) ----
    def offsets(self, platform: Mapping[str, Any]) -> np.ndarray:
        """Offsets of the transducers, (n, 3) [m] (body frame, or NED positions for a fixed array)."""
        raise NotImplementedError

    def lever_arms(self, platform: Mapping[str, Any]) -> np.ndarray:
        """Lever arms of the transducers in NED at the mean heading (level platform), (n, 3) [m]: their positions
        when the platform reference is at the NED origin (default: :meth:`offsets` turned by the heading)."""
        heading = np.radians(platform["heading_deg"])
        c, s = np.cos(heading), np.sin(heading)
        return self.offsets(platform) @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T

    def horizontal_spread(self, platform: Mapping[str, Any]) -> float:
        """The largest horizontal distance between two transducers [m] (the aperture that resolves the diver's
        horizontal position)."""
        xy = self.offsets(platform)[:, :2]
        return float(max(np.linalg.norm(xy[i + 1:] - xy[i], axis=1).max(initial=0.0) for i in range(len(xy))))

    def beacon_count(self, platform: Mapping[str, Any]) -> int:
        """The size of the components' interface of a ``[platform]`` section."""
        return int(self.interface_beacons) if self.interface_beacons is not None else int(platform["beacons"])

    def describe(self, platform: Mapping[str, Any]) -> str:
        """The geometry in a few words (a map panel's title)."""
        raise NotImplementedError

    def design_items(self, count: int, transponders: np.ndarray | None = None,
                     baseline: float | None = None) -> list[str]:
        """The configuration overrides of a design of this system (``sblsim design``): ``platform.system`` and the
        layout of its ``count`` transducers, placed at ``transponders`` (n, 3) NED [m] or on an arm of ``baseline``
        [m] as :attr:`design_layout` says (default: the system alone)."""
        return [f"platform.system={self.name}"]

    # ---- the platform program (casadi) ----
    def body_offsets(self, p: Mapping[str, Any], n_beacons: int, layouts: Sequence[str]) -> list:
        """Body-frame offsets of the transducers as casadi expressions of the platform's parameters ``p``, one
        (3, 1) each (the platform program of the system's interface)."""
        raise NotImplementedError

    def placed_true(self, p: Mapping[str, Any], d: Mapping[str, Any], true):
        """The true transducer positions (3 n, 1) of the platform program where ``p["system"]`` is this system,
        given the platform-mounted ones ``true`` (default: those; a system that overrides this or
        :meth:`placed_broadcast` sets :attr:`places_transducers`)."""
        return true

    def placed_broadcast(self, p: Mapping[str, Any], d: Mapping[str, Any], x: Mapping[str, Any], broadcast):
        """The broadcast transducer positions (3 n, 1) where ``p["system"]`` is this system, given the ones
        computed from GPS and IMU ``broadcast`` (default: those)."""
        return broadcast

    # ---- the receivers (casadi) ----
    def receiver_parameters(self) -> tuple:
        """Parameters every receiver declares for this system (whatever its interface, so that value references
        stay), after the clock's (default none)."""
        return ()

    def receiver_inputs(self) -> tuple:
        """Inputs a receiver of this system's interface adds to the packet (default none)."""
        return ()

    def receiver_update(self, receiver, x: dict, u: dict, p: dict, fresh) -> dict:
        """A receiver's update with this system's packet (systems whose packet is not one range)."""
        raise NotImplementedError

    def receiver_late_inputs(self) -> tuple:
        """Inputs a receiver of this system's interface declares after every other variable (default none)."""
        return ()

    def packet_fix(self, u: dict, p: dict, depth):
        """The diver's position (3, 1) [m] from one packet and the depth reading ``depth`` [m], its covariance
        (3, 3) [m²] and the fit's weighted sum of squared residuals [1] (systems whose packet is not one range)."""
        raise NotImplementedError

    # ---- configuration ----
    def check(self, platform: dict[str, Any], given: set[str]) -> None:
        """Check (and complete) a ``[platform]`` section for this system.

        Raises
        ------
        ModelError
            Naming the field and what is allowed.
        """

    def check_receiver(self, receiver: str, field: str = "simulation.receiver") -> None:
        """Refuse a built-in receiver (``simulation.receiver`` value) that cannot track the system (default: any
        is taken).

        Raises
        ------
        ModelError
            Naming ``field`` and the receivers the system takes.
        """

    def check_diver(self, cfg: Mapping[str, Any], depth: float | None = None) -> None:
        """Check the diver against the system's geometry (default: nothing to check).

        Raises
        ------
        ModelError
        """

    def receiver_ties(self, platform: Mapping[str, Any]) -> dict[str, float]:
        """What the receivers' beacon-uncertainty parameters are tied to: ``beacon_gps_sigma`` [m],
        ``beacon_attitude_sigma_deg`` [deg], ``beacon_arm`` [m], ``gps_correlation_time`` [s] and
        ``attitude_bias_sigma_deg`` [deg] (default: GPS, the IMU's white error with its constant errors (bias,
        axis misalignment) taken as white, the largest arm, the GPS error's correlation time where it is a
        Gauss-Markov process, no attitude states)."""
        constant = (platform["imu_bias_deg"], platform["imu_misalignment_deg"])
        attitude = platform["imu_sigma_deg"] if not any(constant) else math.hypot(platform["imu_sigma_deg"], *constant)
        return {"beacon_gps_sigma": platform["gps_sigma"], "beacon_attitude_sigma_deg": attitude,
                "beacon_arm": float(max(np.linalg.norm(self.offsets(platform), axis=1))),
                "gps_correlation_time": platform["gps_tau"] if platform["gps_model"] == "gauss-markov" else 0.0,
                "attitude_bias_sigma_deg": 0.0}

    def bound_errors(self, cfg: Mapping[str, Mapping[str, Any]]) -> dict[str, float]:
        """The error states of the system's bound (:data:`sblsim.models.bound.ERROR_NAMES`, ``clock`` and
        ``ping_jitter``): the GPS error's std [m] and correlation time [s] where it is a Gauss-Markov process, the
        clock drift's prior std [1] and what its offset adds to a range [m/s] (one-way ranging), the constant
        attitude error's std [rad] (the IMU's bias and axis misalignment), the clock offset's random step at each
        ping [s] (an inverted LBL's pinger); 0 where there is none (default: an SBL's)."""
        platform, acoustics = cfg["platform"], cfg["acoustics"]
        markov, one_way = platform["gps_model"] == "gauss-markov", acoustics["ranging"] == "owtt"
        return {"gps_sigma": platform["gps_sigma"] if markov else 0.0,
                "gps_tau": platform["gps_tau"] if markov else 0.0,
                "clock_drift_sigma": abs(acoustics["clock_drift_ppm"]) * 1e-6 if one_way else 0.0,
                "attitude_sigma": math.radians(math.hypot(platform["imu_bias_deg"], platform["imu_misalignment_deg"])),
                "clock": acoustics["sound_speed_assumed"] if one_way else 0.0, "ping_jitter": 0.0}

    def own_bound(self, parameters: Mapping[str, float]) -> bool:
        """A run of the bound's ``parameters`` steps the system's own bound (:meth:`bound_function`), not the
        metrics pass's range bound (default: where the system has one)."""
        return bool(self.bound_fixed)

    def position_errors(self, platform: Mapping[str, Any]) -> tuple[float, float]:
        """Standard deviations of the broadcast transducer position, (position per axis [m], attitude [rad]):
        the bound's and the map's (default: GPS and IMU)."""
        return platform["gps_sigma"], math.radians(platform["imu_sigma_deg"])

    def angle_sigma_deg(self, platform: Mapping[str, Any]) -> float:
        """The direction-of-arrival std on the array's axis that the receivers (``sigma_angle_deg``) and the bound
        (``angle_sigma_deg``) take [deg]: ``platform.usbl_angle_sigma_deg`` floored at :data:`MIN_ANGLE_SIGMA_DEG`."""
        return max(platform["usbl_angle_sigma_deg"], MIN_ANGLE_SIGMA_DEG)

    # ---- the accuracy limit ----
    def horizontal_std(self, points: np.ndarray, platform: Mapping[str, Any], parameters: Mapping[str, float],
                       sigma_range: float, model=None, heard: np.ndarray | None = None) -> np.ndarray:
        """Horizontal DRMS [m] of a fix from one cycle plus the depth at ``points`` (M, 3) NED [m], (M,): the
        ``drms`` of :meth:`fix_accuracy`, infinite where the information is singular."""
        drms = self.fix_accuracy(points, platform, parameters, sigma_range, model, heard)["drms"]
        return np.where(np.isfinite(drms), drms, np.inf)

    def fix_accuracy(self, points: np.ndarray, platform: Mapping[str, Any], parameters: Mapping[str, float],
                     sigma_range: float, model=None, heard: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """The accuracy of a fix from one cycle plus the depth at ``points`` (M, 3) NED [m]: the Fisher information
        J of the system's measurements (Kay 1993, Section 3.7) as ``drms`` (horizontal, ``sqrt((J⁻¹)_NN +
        (J⁻¹)_EE)``) and ``drms_3d`` (``sqrt(tr J⁻¹)``) [m] and ``log_det`` (``log det J``), each (M,); the map
        and the design's criteria.

        ``parameters`` are the bound's (``noise_variance``, ``attitude_variance``, ``depth_variance``,
        ``angle_sigma_deg``), ``sigma_range`` the range noise std [m], ``model`` a measurement model in place of
        the system's (where it takes one; default the system's). ``heard`` (M, n), where the site decides what
        is heard: each transducer's probability of being heard at each point, which weights its measurements'
        information (a system whose fix needs every packet of its cycle, USBL's one, does not weight it: the
        availability says how often there is a fix), with ``noise_variance`` then per point and transducer.
        """
        raise NotImplementedError

    def measurement_model(self):
        """What one packet measures: the receivers' measurement model (:mod:`sblsim.models.receiver.measurement`)."""
        raise NotImplementedError

    def bound_step(self):
        """One step of the system's PCRB in covariance form, a casadi Function (Tichavský et al. 1998, Eq. (21))."""
        raise NotImplementedError

    def bound_function(self):
        """The system's own PCRB step for the compiled pass, or None (the metrics pass's range bound)."""
        return None


def register(system: type[System]) -> type[System]:
    """Add a system class to :data:`SYSTEMS` (a class decorator); the registry stays in the order of the codes.

    Raises
    ------
    ValueError
        If its name or code is taken.
    """
    instance = system()
    for other in SYSTEMS.values():
        if other.name == instance.name or other.code == instance.code:
            raise ValueError(f"system {instance.name!r} (code {instance.code}) clashes with {other.name!r}")
    ordered = sorted([*SYSTEMS.values(), instance], key=lambda s: s.code)
    SYSTEMS.clear()
    SYSTEMS.update({s.name: s for s in ordered})
    return system


def system(name: str, field: str = "platform.system") -> System:
    """The registered system called ``name``.

    Raises
    ------
    ModelError
        Naming ``field`` and the registry's systems.
    """
    try:
        return SYSTEMS[name]
    except (KeyError, TypeError):
        raise ModelError(f"{field}: {name!r} is not one of {', '.join(SYSTEMS)}") from None


def interface_system(n_beacons: int) -> System:
    """The system whose components' interface has ``n_beacons`` beacon positions: a system of a fixed interface
    size (USBL's one transceiver) where it is that size, else the first of a layout-sized interface (SBL, whose
    interface LBL shares)."""
    for s in SYSTEMS.values():
        if s.interface_beacons == n_beacons:
            return s
    return next(s for s in SYSTEMS.values() if s.interface_beacons is None)


def interface_owners() -> list[System]:
    """The systems that own a components' interface: the first of a layout-sized one (SBL), then each of a fixed
    size (USBL); the others run on their owner's (LBL on SBL's)."""
    layout = next(s for s in SYSTEMS.values() if s.interface_beacons is None)
    return [layout] + [s for s in SYSTEMS.values() if s.interface_beacons is not None]


def interface_systems(n_beacons: int) -> list[System]:
    """Every system that runs on the components' interface of ``n_beacons`` (the platform's ``system``
    parameter chooses among them at run time)."""
    own = interface_system(n_beacons)
    return [s for s in SYSTEMS.values() if s is own or (own.interface_beacons is None and s.interface_beacons is None)]


__all__ = ["MIN_ANGLE_SIGMA_DEG", "MIN_R_SIGMA", "SYSTEMS", "System", "interface_owners", "interface_system",
           "interface_systems", "register", "system"]
