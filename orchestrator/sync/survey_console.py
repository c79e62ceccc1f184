"""The console's line of the receivers' survey error a synchronisation's residuals show
(:mod:`sblsim.orchestrator.sync.survey_seen`), for ``sblsim sync`` and ``sblsim track`` (light: the command line
imports it at start)."""

from __future__ import annotations

import math


def survey_line(seen: dict | None, stated: float | dict | None, source: str | None = None) -> str | None:
    """The console's line of the survey error a synchronisation saw (``seen``: ``sync.json``'s ``survey_error``;
    ``stated``: its ``survey_sigma_m``, the survey's error in its σ; ``source``: its ``survey_sigma_from``,
    ``"seen"`` where the error seen was taken as the survey's, ``"refined"`` a study whose positions are refined
    next); None where no pair was left."""
    if not seen or not seen.get("pairs") or seen.get("excess_z") is None or not math.isfinite(seen["excess_z"]):
        return None
    aside = seen.get("pairs_set_aside") or 0
    said = f"{seen['pairs']} pairs of a sync tag and a receiver" + (
        f", {aside} set aside as a path too long for any position (a reflection)" if aside else "")
    if not seen["seen"]:
        return (f"survey error not seen in the synchronisation's residuals between receivers ({said}: their excess "
                f"over the arrivals' noise {seen['excess_z']:.2g} standard deviations, below {seen['z_seen']:g})")
    if source == "refined":
        given = ("not taken: --refine-positions refines the positions from the pings (its lines below), each refined "
                 "one's own error then in every σ")
    elif source == "seen":
        given = ("taken as the survey's error in every σ: --survey-sigma M states another, 0 the positions as exact, "
                 "--refine-positions refines them")
    elif stated is None:
        given = f"the positions taken as exact: --survey-sigma {seen['survey_sigma_m']:.3g} states it in every σ"
    else:
        given = "stated: " + (f"{stated:g} m" if not isinstance(stated, dict) else "each receiver's") + (
            " (the positions taken as exact)" if stated == 0 else "")
    return (f"survey error seen in the synchronisation's residuals between receivers: {seen['survey_sigma_m']:.3g} "
            f"± {seen['survey_sigma_se_m']:.2g} m per axis ({said}; {given})")


__all__ = ["survey_line"]
