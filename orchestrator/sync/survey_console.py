"""The console's line of the receivers' survey error a synchronisation's residuals show
(:mod:`sblsim.orchestrator.sync.survey_seen`), for ``sblsim sync`` and ``sblsim track``, and the words of its sound
speed (light: the command line imports it at start)."""

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


def speed_said(summary: dict) -> str:
    """The console's words of a synchronisation's sound speed (``summary``: its ``sync.json``'s): given, from a
    series, or estimated with its whole σ (:func:`speed_sigma_text`)."""
    c = summary["sound_speed"]
    if "sound_speed_m_s" not in c:
        return "from the series"
    said = f"{c['sound_speed_m_s']:.1f} m/s ({c['source']})"
    if c.get("source") != "estimated":
        return said
    from sblsim.orchestrator.sync.estimated_speed import estimated_speed  # (the survey error's model: scipy)

    return said + speed_sigma_text(estimated_speed(summary), c.get("sound_speed_sigma_m_s"),
                                   c.get("windows_spread_m_s"))


def speed_sigma_text(speed: dict, fit: float | None, spread: float | None = None) -> str:
    """The estimated sound speed's σ as the console says it: the whole σ a study's tags take as their fallback's
    (``speed``: :func:`~sblsim.orchestrator.sync.estimated_speed.estimated_speed`), the fit's (with a season's
    windows' ``spread`` in it, where they disagree: :func:`~sblsim.models.sync.windows.season_slowness`) and the
    survey's share in it [m/s]; or why none is taken (the survey's share not bounded); nothing without the fit's σ."""
    if fit is None:
        return ""
    fitted = f"the fit's {fit:.2g}" + (f" with the windows' spread {spread:.2g}" if spread else "")
    if speed.get("sound_speed_sigma_m_s") is None:
        return (f", {fitted} m/s; the survey's share of its error not bounded (too few pairs of a sync tag and "
                "another receiver): a study's tags keep the default's")
    windows = speed.get("sound_speed_windows")
    return (f", σ {speed['sound_speed_sigma_m_s']:.2g} m/s ({fitted}, the survey's share "
            f"{speed['sound_speed_survey_sigma_m_s']:.2g})") + (
        f"; a study's tags rescaled by the {len(windows)} windows' own speeds, σ "
        f"{speed['sound_speed_windows_sigma_m_s']:.2g} m/s" if windows else "")


__all__ = ["speed_said", "speed_sigma_text", "survey_line"]
