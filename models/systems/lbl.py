"""Long baseline (LBL): transponders on the seafloor, at surveyed positions.

Transponder i stands at NED ``(a_ix, a_iy, platform.seafloor_depth)``, the
layout's points (a cross or circle of ``platform.baseline``; a custom layout's
offsets are the NED positions themselves); they do not move and need no GPS or
IMU. The positions the packets carry are the *surveyed* ones, ``b_i + s_i``,
``s_i ~ N(0, σ_survey² I)`` drawn once per run (a bias, not a noise). Ranging
and the receivers' model are SBL's (it shares the SBL interface: the
platform's ``system`` parameter switches the positions at run time); the
receivers' beacon uncertainty, the bound and the map take the survey error in
place of GPS and no attitude error.

References
----------
Vickery, "Acoustic positioning systems. A practical overview of current
systems", Proc. 1998 Workshop on Autonomous Underwater Vehicles, IEEE, 1998
(LBL: seafloor transponders, surveyed positions).
"""

from __future__ import annotations

from typing import Any, Mapping

import casadi as ca
import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.systems import register
from sblsim.models.systems.sbl import SBL, _layout_words
from sblsim.models.table_text import format_table
from sblsim.models.target.core import file_waypoints


@register
class LBL(SBL):
    """Long baseline: N surveyed transponders on the seafloor (docs/model.md, "Systems")."""

    name = "lbl"
    code = 1
    title = "long baseline"
    words = "4 transponders on a 50 m circle at platform.seafloor_depth"
    compare_defaults = ("platform.layout=circle", "platform.beacons=4", "platform.baseline=50")
    marker = "transponders"
    places_transducers = True
    design_layout = "seafloor"
    design_grades = ("ranging",)

    def offsets(self, platform: Mapping[str, Any]) -> np.ndarray:
        """The transponders' NED positions relative to the mooring point (n, 3) [m]: the layout's points at
        ``seafloor_depth`` (a custom layout's offsets as given)."""
        offsets = super().offsets(platform)
        if platform["layout"] != "custom":
            offsets[:, 2] = platform["seafloor_depth"]
        return offsets

    def lever_arms(self, platform: Mapping[str, Any]) -> np.ndarray:
        """The transponders' positions (no heading turns them)."""
        return self.offsets(platform)

    def describe(self, platform: Mapping[str, Any]) -> str:
        return (f"{len(self.offsets(platform))} transponders, {_layout_words(platform)}, seafloor at "
                f"{platform['seafloor_depth']:g} m")

    def placed_true(self, p, d, true):
        """The seafloor positions (``d["seafloor"]``) where the platform's ``system`` parameter is LBL."""
        return ca.if_else(p["system"] == self.code, d["seafloor"], true)

    def placed_broadcast(self, p, d, x, broadcast):
        """The surveyed positions (``d["seafloor"] + x["survey"]``) where the platform's ``system`` parameter is
        LBL."""
        surveyed = d["seafloor"] + x["survey"]
        return ca.if_else(p["system"] == self.code, surveyed, broadcast)

    def design_items(self, count: int, transponders: np.ndarray | None = None,
                     baseline: float | None = None) -> list[str]:
        """``count`` transponders at ``transponders`` (n, 3), NED [m] (a custom layout)."""
        return [f"platform.system={self.name}", "platform.layout=custom", f"platform.beacons={count}",
                f"platform.beacon_offsets={format_table(transponders)}"]

    def check_diver(self, cfg: Mapping[str, Any], depth: float | None = None) -> None:
        """Refuse a diver that is not above the seafloor transponders.

        The diver's depth is ``depth`` (a map's) when given, else ``target.depth`` (the start of a random walk),
        or the deepest waypoint of a trajectory file.

        Raises
        ------
        ModelError
            Naming ``platform.seafloor_depth``, the diver's depth and what to do.
        """
        platform, target = cfg["platform"], cfg["target"]
        if platform["layout"] == "custom":
            return
        if depth is not None:
            where = "the map's depth"
        elif target["trajectory"] == "file":
            depth, where = float(file_waypoints(target)[:, 3].max()), "the deepest waypoint of target.trajectory_file"
        else:
            depth, where = float(target["depth"]), "target.depth"
        if depth >= platform["seafloor_depth"]:
            raise ModelError(f"platform.seafloor_depth: {platform['seafloor_depth']:g} m is not below the diver "
                             f"({depth:g} m, {where}); the LBL transponders stand on the seafloor: set it to the "
                             "site's depth, below the diver")

    def receiver_ties(self, platform: Mapping[str, Any]) -> dict[str, float]:
        """Surveyed transponders: the survey error in place of GPS, no attitude, no arm, no error states."""
        return {"beacon_gps_sigma": platform["survey_sigma"], "beacon_attitude_sigma_deg": 0.0, "beacon_arm": 0.0,
                "gps_correlation_time": 0.0, "attitude_bias_sigma_deg": 0.0}

    def position_errors(self, platform: Mapping[str, Any]) -> tuple[float, float]:
        """The survey error, no attitude error."""
        return platform["survey_sigma"], 0.0

    def bound_errors(self, cfg: Mapping[str, Mapping[str, Any]]) -> dict[str, float]:
        """The clock's (one-way ranging); surveyed transponders have no GPS or attitude."""
        return {**super().bound_errors(cfg), "gps_sigma": 0.0, "gps_tau": 0.0, "attitude_sigma": 0.0}


__all__ = ["LBL"]
