"""Short baseline (SBL): beacons on the floating platform, each broadcasting its position (GPS and IMU).

The beacons sit on a cross of the paper's 4 arms (``platform.layout = "cross"``),
N equally spaced on a circle (``circle``, ``platform.beacons`` N in [3, 16]) or at
given body-frame offsets (``custom``), all at ``platform.transducer_depth`` below
the platform reference, which the waves move; the platform broadcasts
``b̃_i = p̃ + R(θ̃) a_i`` from the GPS position and the IMU attitude
(:mod:`sblsim.models.platform.core`). One packet measures one range (OWTT or
TWTT); the receivers take ranges plus the depth
(:class:`~sblsim.models.receiver.measurement.RangeDepthModel`); the bound and
the accuracy map are the range bound of :mod:`sblsim.models.bound` (with error states where a run has
error sources that are not white: :func:`sblsim.models.error_bound.error_bound_step`).

References
----------
Cario, Casavola, Gagliardi, Lupia, Severino, "Accurate Localization in
Acoustic Underwater Localization Systems", Sensors 21(3):762, 2021,
doi:10.3390/s21030762 (Section 3, the SBL cross).
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from sblsim.models.bound import MODEL, bound_step
from sblsim.models.declarations import ModelError
from sblsim.models.design.information import layout_values
from sblsim.models.error_bound import ERROR_FIXED, ERROR_STEPS, compiled_error_bound
from sblsim.models.platform.core import MAX_BEACONS, MIN_BEACONS
from sblsim.models.platform.geometry import cross_offsets, layout_offsets, parse_offsets
from sblsim.models.systems import System, register


@register
class SBL(System):
    """Short baseline: N beacons on the platform (docs/model.md, "Systems")."""

    name = "sbl"
    code = 0
    title = "short baseline"
    words = "the paper's cross at 3 m"
    compare_defaults = ("platform.layout=cross", "platform.baseline=3")  # the paper's cross (its LOW corner)
    marker = "beacons"
    design_layout = "platform"
    design_grades = ("gps", "imu", "ranging")

    def offsets(self, platform: Mapping[str, Any]) -> np.ndarray:
        """Body-frame offsets (n, 3) [m]: the cross has the paper's 4 beacons, the circle ``platform.beacons``
        (default 4), a custom layout as many as ``beacon_offsets`` lists (:func:`layout_offsets`)."""
        n = int(platform.get("beacons", 4)) if platform["layout"] == "circle" else 4
        return layout_offsets(platform["layout"], platform["baseline"], platform["transducer_depth"],
                              platform["beacon_offsets"], n)

    def describe(self, platform: Mapping[str, Any]) -> str:
        return f"{len(self.offsets(platform))} beacons, {_layout_words(platform)}"

    def body_offsets(self, p: Mapping[str, Any], n_beacons: int, layouts: Sequence[str]) -> list:
        """The cross (or circle) of ``baseline`` at ``transducer_depth``, or the custom offsets
        (``beacon<i>_offset_<a>``)."""
        cross = cross_offsets(p["baseline"], p["transducer_depth"], n_beacons)
        custom = [ca.vertcat(*[p[f"beacon{i + 1}_offset_{a}"] for a in "xyz"]) for i in range(n_beacons)]
        return [ca.if_else(p["layout"] == layouts.index("custom"), c, a) for a, c in zip(cross, custom)]

    def check(self, platform: dict[str, Any], given: set[str]) -> None:
        """Tie ``platform.beacons`` to the layout: the cross has the paper's 4 beacons, a custom layout as many
        as its offsets list (the key is filled with that count when the user did not set it), the circle the
        key's.

        Raises
        ------
        ModelError
            ``beacons`` other than 4 with the cross, a custom layout whose count differs from a given
            ``beacons`` or lies outside [3, 16].
        """
        layout, n = platform["layout"], platform["beacons"]
        if layout == "cross" and n != 4:
            raise ModelError(f"platform.beacons: {n} with platform.layout = 'cross' (the paper's 4 beacons); use "
                             "platform.layout = 'circle' for N equally spaced beacons")
        if layout == "custom":
            count = parse_offsets(platform["beacon_offsets"]).shape[0]
            if "beacons" in given and count != n:
                raise ModelError(f"platform.beacons: {n}, but platform.beacon_offsets lists {count} beacons")
            if not MIN_BEACONS <= count <= MAX_BEACONS:
                raise ModelError(f"platform.beacon_offsets: {count} beacons; allowed [{MIN_BEACONS}, "
                                 f"{MAX_BEACONS}]")
            platform["beacons"] = count

    def measurement_model(self):
        """Fresh ranges plus the depth (:class:`~sblsim.models.receiver.measurement.RangeDepthModel`, the bound's)."""
        return MODEL

    bound_fixed = ERROR_FIXED
    bound_steps = ERROR_STEPS

    def bound_step(self):
        """The range bound's step (:func:`sblsim.models.bound.bound_step`), which the compiled metrics pass steps."""
        return bound_step()

    def bound_function(self):
        """The bound with error states (:func:`sblsim.models.error_bound.compiled_error_bound`), stepped for a run
        that has one (:meth:`own_bound`)."""
        return compiled_error_bound()

    def own_bound(self, parameters: Mapping[str, float]) -> bool:
        """A run whose errors include one the bound carries as a state (a Gauss-Markov GPS error, a clock's drift,
        a constant attitude error: :meth:`bound_errors`) steps the bound with error states; every other run the
        metrics pass's range bound."""
        return any(parameters[k] > 0.0 for k in ("gps_sigma", "clock_drift_sigma", "attitude_sigma"))

    def design_items(self, count: int, transponders: np.ndarray | None = None,
                     baseline: float | None = None) -> list[str]:
        """``count`` beacons on a circle of radius ``baseline`` [m] on the platform."""
        return [*super().design_items(count), "platform.layout=circle", f"platform.beacons={count}",
                f"platform.baseline={baseline!r}"]

    def fix_accuracy(self, points: np.ndarray, platform: Mapping[str, Any], parameters: Mapping[str, float],
                     sigma_range: float, model=None, heard: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """One round of fresh ranges (one per beacon) plus the depth
        (:func:`sblsim.models.design.information.layout_values` of the beacons at their lever arms, ``model`` the
        range model, default the receivers'); with ``heard``, each beacon's probability of being heard at each
        point (M, n), its range weighted by it and ``parameters["noise_variance"]`` given per point and beacon,
        (M, n)."""
        arms = self.lever_arms(platform)
        return layout_values(points, arms, arms, 1.0 if heard is None else heard, parameters["noise_variance"],
                             parameters["attitude_variance"], parameters["depth_variance"],
                             MODEL if model is None else model)


def _layout_words(platform: Mapping[str, Any]) -> str:
    return "custom layout" if platform["layout"] == "custom" else f"{platform['baseline']:g} m {platform['layout']}"


__all__ = ["SBL"]
