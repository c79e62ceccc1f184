"""Two tags under one transmitter id: a times-of-arrival matrix whose trusted single-ping fixes jump between two
places as no animal moves is refused (:func:`~sblsim.models.tracking.twins.two_places`); one whose fixes show a
second place heard at once (:func:`~sblsim.models.tracking.two_places.places_at_once`) is tracked at its first place,
the second place's rows flagged at their fixes (:func:`second_place`, :func:`at_second_place`), or refused where no
place holds a clear majority.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.twins import MAX_SPEED, MIN_GROUP_SHARE, two_places
from sblsim.models.tracking.two_places import places_at_once

if TYPE_CHECKING:
    from sblsim.orchestrator.io.frames import Frame


def _one_tag(toa_path: Path, fixes: np.ndarray, emissions: np.ndarray, covariances: np.ndarray,
             trusted: np.ndarray) -> None:
    """Refuse a times-of-arrival matrix whose trusted single-ping fixes jump between two places as no animal moves:
    two tags under one transmitter id (:func:`~sblsim.models.tracking.twins.two_places`), named by the file's stem.

    Raises
    ------
    ModelError
        One line naming the transmitter, the two places, the jumps and what is allowed.
    """
    found = two_places(fixes[trusted], emissions[trusted], covariances[trusted])
    if found is None:
        return
    (x0, y0), (x1, y1) = found.centres
    raise ModelError(f"transmitter {Path(toa_path).stem}: looks like two tags, at ({x0:.0f}, {y0:.0f}) m and "
                     f"({x1:.0f}, {y1:.0f}) m, {found.separation:.0f} m apart ({found.shares[0]:.0%} and "
                     f"{found.shares[1]:.0%} of {found.fixes} trusted fixes): {found.jumps} of {found.steps} steps "
                     f"between consecutive fixes are faster than {MAX_SPEED:g} m/s; allowed: one tag's pings (two "
                     "tags sharing an id: split its detections by place or by receiver)")


#: The quality reason of a row heard from a second place at once (:func:`second_place`).
TWO_PLACES_REASON = "two_places"


@dataclass(frozen=True)
class SecondPlace:
    """The rows of one id heard from a second place at once (:func:`second_place`): ``rows`` (m,) the mask, their
    single-ping fixes (``positions`` (k, dim) [m], ``times`` (k,) [s], ``covariances`` (k, dim, dim) [m²], ``heard``
    (k,) the arrivals each kept) and ``summary.json``'s ``two_places`` (``summary``, its ``warning`` the line the
    console prints)."""

    rows: np.ndarray
    positions: np.ndarray
    times: np.ndarray
    covariances: np.ndarray
    heard: np.ndarray
    summary: dict[str, Any]


def _where(places: np.ndarray, lat_lon: np.ndarray | None) -> list[str]:
    """Each place as the console says it: x, y in the frame [m], and latitude, longitude (``lat_lon`` (2, 2) [°])
    where the frame is known."""
    out = [f"x {x:.0f}, y {y:.0f} m" for x, y in places]
    if lat_lon is not None:
        out = [f"{o} (lat {a:.5f}°, lon {b:.5f}°)" for o, (a, b) in zip(out, lat_lon)]
    return out


def second_place(toa: np.ndarray, fixes: tuple[np.ndarray, ...], trusted: np.ndarray, protection: np.ndarray,
                 frame: Frame | None = None) -> tuple[np.ndarray, tuple[np.ndarray, ...], SecondPlace | None]:
    """The rows of a second place heard at once (:func:`~sblsim.models.tracking.two_places.places_at_once`) taken
    out of the track: their arrivals and fixes blanked (NaN) so that no estimator is drawn to them, kept to be
    written at their fixes and flagged :data:`TWO_PLACES_REASON`; where the second place holds a fifth of the
    trusted fixes or more (:data:`~sblsim.models.tracking.twins.MIN_GROUP_SHARE`: no place holds a clear majority,
    no track is one tag's) the pings are refused.

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s].
    fixes : tuple
        The single-ping fixes as :func:`~sblsim.models.receiver.toa_tracking.fix_pings` gives them: positions
        (m, dim) [m], emission times (m,) [s], covariances (m, p, p), the arrivals used (m, n), their χ² (m,).
    trusted : ndarray of bool, (m,)
        The fixes the checks trust.
    protection : ndarray, (m,)
        Each fix's protection level [m] (:func:`~sblsim.models.tracking.integrity.protection_levels`).
    frame : Frame, optional
        The receivers' frame (the places in latitude and longitude too).

    Returns
    -------
    toa, fixes, second
        The matrix and the fixes with the second place's rows blanked, and those rows (None where there is none).

    Raises
    ------
    ModelError
        One line naming the two places, where the second holds a fifth of the trusted fixes or more.
    """
    fx, fe, fc, used, chi2 = fixes
    found = places_at_once(fx, fe, fc, trusted, protection)
    if found is None:
        return toa, fixes, None
    rows = found.second
    lat_lon = None if frame is None else np.column_stack(frame.to_latlon(found.places[:, 0], found.places[:, 1]))
    (one, other), (n1, n2) = _where(found.places, lat_lon), found.fixes
    said = (f"{n1:,} trusted fixes ({found.shares[0]:.0%}) around {one} and {n2:,} ({found.shares[1]:.0%}) around "
            f"{other}, {found.separation:.0f} m apart, {found.out_of_reach} of the second place's fixes out of reach "
            f"of the first's at {MAX_SPEED:g} m/s")
    if found.shares[1] >= MIN_GROUP_SHARE:
        raise ModelError(f"this id looks like two tags heard from two places at once: {said}; allowed: one tag's "
                         "pings (two tags sharing an id: split its detections by place or by receiver)")
    dim = fx.shape[1]
    second = SecondPlace(rows, fx[rows], fe[rows], fc[rows][:, :dim, :dim], used[rows].sum(axis=1), {
        "places_m": found.places.tolist(), "places_lat_lon": None if lat_lon is None else lat_lon.tolist(),
        "separation_m": found.separation,
        "trusted_fixes": list(found.fixes), "shares": list(found.shares), "out_of_reach": found.out_of_reach,
        "second_span_s": list(found.span), "rows": int(rows.sum()), "reason": TWO_PLACES_REASON,
        "warning": f"one id heard from two places at once (two tags, or a code collision): {said}; the "
                   f"{int(rows.sum()):,} rows of the second place flagged {TWO_PLACES_REASON} at their single-ping "
                   "fixes, the track made of the first place's"})
    toa = toa.copy()
    toa[rows] = np.nan
    blanked = [a.copy() for a in fixes]
    for a in blanked:
        a[rows] = False if a.dtype == bool else np.nan
    return toa, tuple(blanked), second


def at_second_place(frames: dict[str, Any], covariances: dict[str, np.ndarray], flagged: dict[str, int], main: str,
                    second: SecondPlace, placed: Callable[[np.ndarray, np.ndarray], dict[str, Any]]) -> None:
    """The rows of the second place in the track (``frames[main]``: added where the track has none) at their
    single-ping fixes, with their covariances (``covariances[main]``); in every estimator's rows ``flagged``,
    :data:`TWO_PLACES_REASON`, counted in ``flagged`` (``placed``: a row's time and place as the track's columns,
    from emission times (k,) [s] and positions (k, dim) [m])."""
    import pandas as pd

    pings = np.flatnonzero(second.rows)
    frame = frames[main]
    extra = np.setdiff1d(pings, frame["ping"].to_numpy())
    if len(extra):
        frame = pd.concat([frame, pd.DataFrame({"estimator": main, "ping": extra})], ignore_index=True)
        order = np.argsort(frame["ping"].to_numpy(), kind="stable")
        frames[main] = frame = frame.iloc[order].reset_index(drop=True)
        covariances[main] = np.concatenate([covariances[main], np.full((len(extra), 2, 2), np.nan)])[order]
    at = np.flatnonzero(np.isin(frame["ping"].to_numpy(), pings))
    k = np.searchsorted(pings, frame["ping"].to_numpy()[at])
    cov = second.covariances[k]
    values = placed(second.times[k], second.positions[k]) | {
        "time": second.times[k], "receivers_heard": second.heard[k],
        **{f"sigma_{a}": np.sqrt(cov[:, j, j]) for j, a in enumerate("xyz"[:cov.shape[1]])}}
    for column, value in values.items():
        frame.loc[frame.index[at], column] = value
    covariances[main][at] = cov[:, :2, :2]
    for estimator, rows in frames.items():
        mine = np.isin(rows["ping"].to_numpy(), pings)
        rows.loc[mine, "quality"] = "flagged"
        rows.loc[mine, "quality_reason"] = TWO_PLACES_REASON
        flagged[estimator] = int((rows["quality"] == "flagged").sum())


__all__ = ["TWO_PLACES_REASON", "SecondPlace", "at_second_place", "second_place"]
