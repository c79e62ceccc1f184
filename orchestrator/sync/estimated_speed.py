"""The sound speed a synchronisation estimated with its clocks (its ``sync.json``'s ``sound_speed``) and its σ as a
study's tags take it as their fallback (:func:`estimated_speed`; ``study.json``'s ``clocks``,
:func:`~sblsim.orchestrator.telemetry.study_offsets.study_speed`): the fit's, the survey error's share through the
array's scale, and a season's windows' own speeds where they differ (:func:`season_series`)."""

from __future__ import annotations

import numpy as np

from sblsim.models.sync.survey_error import Z_SEEN


def estimated_speed(summary: dict) -> dict:
    """The sound speed [m/s] a synchronisation estimated with its clocks (``summary``: its ``sync.json``'s) and its
    σ [m/s] (``study.json``'s ``clocks``: each tag's fallback,
    :func:`~sblsim.orchestrator.telemetry.study_offsets.study_speed`): the fit's and the survey error's share
    through the array's scale (:mod:`sblsim.models.sync.survey_error`, ``speed_scale_sigma_per_m``), in quadrature:
    a position off stretches the sync tags' ranges, which the speed takes; the fit's σ alone does not count it. The
    survey error is the one taken (``survey_sigma_m``; each receiver's: their RMS), else the one seen, else the most
    the residuals' test could have missed (:data:`~sblsim.models.sync.survey_error.Z_SEEN` standard errors); where
    neither that nor the scale is determined (too few pairs), the σ is None: the speed is said, not taken. A
    season's windows' own speeds where they differ (:func:`season_series`). Nothing (an empty dict) where the speed
    was given or the fit has no σ."""
    speed = summary.get("sound_speed") or {}
    fit = speed.get("sound_speed_sigma_m_s")
    if speed.get("source") != "estimated" or fit is None:
        return {}
    c = float(speed["sound_speed_m_s"])
    seen = summary.get("survey_error") or {}
    taken = summary.get("survey_sigma_m")  # (each receiver's: their RMS)
    if isinstance(taken, dict):
        taken = float(np.sqrt(np.mean(np.square(list(taken.values())))))
    elif taken is None and seen.get("seen"):
        taken = seen.get("survey_sigma_m")
    elif taken is None and seen.get("survey_sigma_se_m") is not None:  # what the test could have missed
        taken = Z_SEEN * float(seen["survey_sigma_se_m"])
    scale = seen.get("speed_scale_sigma_per_m") if taken else 0.0
    share = None if taken is None or scale is None else c * float(taken) * float(scale)
    return {"sound_speed_m_s": c, "sound_speed_sigma_m_s": None if share is None else float(np.hypot(fit, share)),
            "sound_speed_survey_sigma_m_s": share} | ({} if share is None else season_series(summary, share))


def season_series(summary: dict, share: float) -> dict:
    """A season's windows' own sound speeds where they differ beyond their σ (``summary``: a ``sync.json``'s,
    ``sound_speed.windows_spread_m_s`` above 0: :func:`~sblsim.models.sync.windows.season_slowness`): each window's
    middle [s since 1970 UTC] and speed [m/s] (``sound_speed_windows``, each tag's arrivals rescaled by them to the
    season's speed: :func:`~sblsim.orchestrator.tracks.speed.season_rescaled`) and the σ [m/s] the season's speed
    then has for a tag (``sound_speed_windows_sigma_m_s``: the windows' largest σ and the survey's ``share`` [m/s],
    in quadrature); nothing otherwise."""
    windows = summary.get("windows") or {}
    speeds, sigmas = windows.get("sound_speed_m_s"), windows.get("sound_speed_sigma_m_s")
    if not (summary["sound_speed"].get("windows_spread_m_s") or 0.0) > 0.0 or not speeds or None in (sigmas or [None]):
        return {}
    edges = np.asarray(windows["edges"], float)
    return {"sound_speed_windows": np.c_[(edges[:-1] + edges[1:]) / 2.0, speeds].tolist(),
            "sound_speed_windows_sigma_m_s": float(np.hypot(max(sigmas), share))}


__all__ = ["estimated_speed", "season_series"]
