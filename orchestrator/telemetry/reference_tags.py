"""Reference tags: the study's own accuracy check (``sblsim track``'s ``reference_tags.csv``, ``study.json``'s
``reference_tags`` and one console line each).

A study's only truth is where its still tags are. Two kinds are scored, each per tag and pooled:

* **a reference tag** (the tag sheet's role ``reference``, tracked as still: one place for all its pings,
  :mod:`sblsim.models.tracking.still_tag`) at a known position: the sheet's ``lat``, ``lon`` [, ``depth_m``]
  (projected into the study's frame), else the position of the deployment it sits at, the one the sheet's ``receiver``
  (or ``station``) cell names or else the one whose sync-tag cell names it (``truth`` says which). Its place (its
  first, where it moved) against that position: the error [m] (2-D, and 3-D where both have a depth), its σ [m] (the
  2-D covariance's root trace), its 2-D NEES ``eᵀ (P + Q − X − Xᵀ)⁻¹ e`` and its rows flagged. ``P`` is the place's
  covariance as the tracker reports it (the pooled fit's, its consider terms: the clocks' offsets' uncertainty, the
  sound speed's, and the receivers' jackknife, which measures what the other receivers' positions and paths do to it);
  ``Q`` the position's own error, ``survey_sigma_m`` per horizontal axis where the sheet states it, else at a
  deployment the study's stated survey error (``--survey-sigma`` without the refinement), else none (the position
  taken as exact: said); ``X`` the place's covariance with that position's error where both are one survey's (a tag at
  a deployment whose survey error the tracker took: what that receiver's error moved the place by,
  :func:`~sblsim.models.tracking.still_tag.survey_cross`; else none). Beside it the tracker's single-ping
  least-squares fixes' median error (the naive estimate). A tag tracked as moving (``motion`` ``moving``) is scored
  row by row (its rows not flagged: the median error, the mean NEES of ``diag(sigma_x², sigma_y²) + Q``).
* **every sync tag left out of the synchronisation in turn**: the synchronisation's own leave-one-out
  (``sync_tags.csv``, :mod:`sblsim.orchestrator.sync.sync_tags`, with the clocks fitted without its arrivals), taken
  as it is, not fitted again: its one place from all its arrivals, its own receiver's too, by the reference tags'
  still-tag model (``place_*``: error, σ, NEES, emissions flagged) against its receiver's position, its
  single-emission fixes' median error beside it; a table without places (an older one) scored by those fixes (their
  median error, median σ and mean NEES, the emissions without a trusted fix; pooled as the synchronisation pools
  them: the mean NEES of those inside the array). Pooled: the median of the tags' errors, the mean NEES of the places.
* **both kinds together** (``still``): every still tag scored by one place, their median error and mean NEES.

A still tag whose NEES is beyond χ²(2)'s :data:`BEYOND_LEVEL` quantile is said in a warning: it moved, its
position is wrong, or a receiver's is. For a tag at a deployment, where the clocks were synchronised here, the
warning says how much the synchronisation's residuals at that receiver keep that its clock does not explain: the
root mean square over the other receivers' sync tags it hears of their arrivals' median residual
(:func:`persistent_residual`), beside the array's median of the same (a receiver's position off, or a path's
reflection, shows there). A reference tag whose deployment's sync-tag cell names it was in the synchronisation too
(``in_sync``): its clocks were fitted with its arrivals, its score is not independent of them.

Units: metres [m].
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd
from scipy.stats import chi2

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.still_tag import place_score, survey_cross
from sblsim.orchestrator.readers.cells import numbers, pattern
from sblsim.orchestrator.readers.deployments import Deployments
from sblsim.orchestrator.readers.limits import IDENTIFIER, MAX_COORDINATE
from sblsim.orchestrator.readers.tag_sheet import TagSpec
from sblsim.orchestrator.readers.transmitters import TRANSMITTER, match
from sblsim.orchestrator.sync.clocks import _columns, _in_folder
from sblsim.orchestrator.sync.survey_seen import pairs
from sblsim.orchestrator.sync.sync_tags import PLACE_COLUMNS

#: A reference tag is said to lie beyond its σ where its 2-D NEES passes χ²(2)'s quantile at this level.
BEYOND_LEVEL = 0.99
#: ``reference_tags.csv``'s columns: ``kind`` ``reference`` or ``sync_left_out``; ``truth`` where the position
#: scored against comes from; ``truth_*`` that position (in the frame [m], WGS 84 [°]); ``x_m``, ``y_m``, ``z_m`` the
#: tag's place and ``error_east_m``, ``error_north_m`` its offset from that position (the frame's x and y);
#: ``error_m``, ``sigma_m``, ``nees``; ``rows`` and ``flagged``; ``scored_by`` how: ``one place`` (a still tag's, a
#: sync tag's as a reference tag's), ``its rows`` (a reference tag tracked as moving: the median error, the mean NEES
#: of its rows not flagged) or ``single-emission fixes`` (a sync tag without a place: its fixes' median position,
#: median error, median σ and mean NEES; its emissions and those without a trusted fix).
COLUMNS = ("tag", "kind", "truth", "receiver", "truth_x_m", "truth_y_m", "truth_z_m", "truth_lat", "truth_lon", "x_m",
           "y_m", "z_m", "error_m", "error_east_m", "error_north_m", "error_3d_m", "sigma_m", "survey_sigma_m", "nees",
           "beyond_sigma", "rows", "flagged", "share_flagged", "verdict", "scored_by", "single_fix_median_error_m",
           "receiver_persistent_m", "in_sync", "inside_array")


def beyond() -> float:
    """The 2-D NEES beyond which a reference tag is said to be off: χ²(2)'s :data:`BEYOND_LEVEL` quantile."""
    return -2.0 * float(np.log1p(-BEYOND_LEVEL))


def consistent(n: int) -> list[float]:
    """The 90 % interval of the mean of ``n`` 2-D NEES whose σ holds: χ²(2n) / n's 5 % and 95 % quantiles (a pooled
    NEES outside it says the σ does not hold; three tags' mean lies anywhere in about [0.55, 4.2])."""
    return [float(chi2.ppf(0.05, 2 * n) / n), float(chi2.ppf(0.95, 2 * n) / n)]


def persistent_residual(paired: pd.DataFrame, receiver: str) -> float:
    """[m] What the synchronisation's residuals at ``receiver`` keep that its clock does not explain: the root mean
    square, weighted by their arrivals, of the median residual of each other receiver's sync tag it hears (at least
    :data:`~sblsim.models.sync.survey_error.MIN_PAIR_ARRIVALS` kept arrivals; its own sync tag, at no distance, left
    out); NaN where none.

    Parameters
    ----------
    paired : pandas.DataFrame
        The residuals' pairs (:func:`~sblsim.orchestrator.sync.survey_seen.pairs` of ``residuals.csv``):
        ``receiver``, ``median`` [m], ``count``.
    receiver : str
    """
    mine = paired[paired["receiver"] == receiver]
    if not len(mine):
        return float("nan")
    return float(np.sqrt(np.average(mine["median"] ** 2, weights=mine["count"])))


def _deployment(spec: TagSpec, table: pd.DataFrame) -> tuple[pd.DataFrame, str] | str:
    """The deployment a reference tag sits at and how it was found, else why none."""
    if spec.receiver:
        for key in ("receiver", "serial", "station"):
            rows = table[table[key].astype(str) == spec.receiver]
            if len(rows) == 1:
                return rows, f"the tag sheet's receiver {spec.receiver}"
            if len(rows) > 1:
                return (f"the tag sheet's receiver {spec.receiver!r} names {len(rows)} deployments (give one "
                        f"deployment's name: {', '.join(rows['receiver'].astype(str).head(4))})")
        return f"the tag sheet's receiver {spec.receiver!r} names no deployment of the study"
    cells = sorted(set(table["sync_tag"].astype(str)) - {""})
    try:
        cell = match(spec.transmitter, cells)
    except ModelError as exc:
        return str(exc)
    if cell is None:
        return "no surveyed position (lat, lon in the tag sheet) and no deployment it sits at (a receiver column)"
    return table[table["sync_tag"].astype(str) == cell].head(1), "its deployment's sync-tag cell"


def truth_of(spec: TagSpec, deployments: Deployments) -> dict[str, Any] | str:
    """A reference tag's known position (the module docstring): ``truth`` (where it comes from), ``receiver`` (the
    deployment it sits at, ``""``), ``xyz`` (3,) [m] in the study's frame (z NaN where no depth), ``lat``, ``lon``,
    ``survey`` [m] (NaN: not stated) and ``in_sync``; else the one line of why it has none."""
    table = deployments.table
    in_sync = False
    if np.isfinite(spec.lat):
        if deployments.frame is None:
            return "a surveyed lat, lon and receivers in a local frame without a CRS (give --crs)"
        x, y = deployments.frame.from_latlon(np.array([spec.lat]), np.array([spec.lon]))
        where = {"truth": "the tag sheet's lat, lon", "receiver": "", "xyz": np.array([x[0], y[0], np.nan]),
                 "lat": spec.lat, "lon": spec.lon}
    else:
        found = _deployment(spec, table)
        if isinstance(found, str):
            return found
        row, how = found[0].iloc[0], found[1]
        where = {"truth": f"deployment {row['receiver']} ({how})", "receiver": str(row["receiver"]),
                 "xyz": row[["x", "y", "z"]].to_numpy(float), "lat": float(row["lat"]), "lon": float(row["lon"])}
        cell = str(row["sync_tag"])
        in_sync = bool(cell) and match(spec.transmitter, [cell]) is not None
    if np.isfinite(spec.depth):
        where["xyz"][2] = -spec.depth
    return where | {"survey": spec.survey_sigma, "in_sync": in_sync}


def _row(track: pd.DataFrame) -> tuple[int, int]:
    """A track's rows positioned and flagged."""
    placed = np.isfinite(track[["x", "y"]].to_numpy(float)).all(axis=1)
    return int(placed.sum()), int(((track["quality"] == "flagged").to_numpy() & placed).sum())


def score_reference(tag: str, outcome, truth: dict[str, Any]) -> dict[str, Any]:
    """A tracked reference tag's row of ``reference_tags.csv`` (the module docstring).

    Parameters
    ----------
    tag : str
        Its name in ``tracks.csv``.
    outcome : TrackOutcome
        Its tracking's (:class:`~sblsim.orchestrator.tracks.outcome.TrackOutcome`: ``track``, ``estimates``,
        ``summary``).
    truth : dict
        :func:`truth_of`'s.
    """
    s, track = outcome.summary, outcome.track
    q = np.asarray(truth["xyz"], float)
    survey = float(truth["survey"]) if np.isfinite(truth["survey"]) else 0.0
    Q = survey**2 * np.eye(2)
    still = (s.get("motion") or {}).get("still")
    rows, flagged = _row(track)
    if still is not None:  # one place (its first, where it moved) and its covariance
        place = np.asarray(still["place"], float)
        e, error, sigma, nees = place_score(still, q, Q, _cross(s, still, truth["receiver"], survey))
        verdict, scored_by = still["verdict"], "one place"
        depth = place[2] - q[2] if len(place) > 2 else np.nan
    else:  # tracked as moving: its rows not flagged, one by one
        ok = track[(track["quality"] != "flagged") & track["x"].notna()]
        d = ok[["x", "y"]].to_numpy(float) - q[:2]
        var = ok[["sigma_x", "sigma_y"]].to_numpy(float) ** 2 + survey**2
        place = np.median(ok[["x", "y"] + (["z"] if "z" in ok else [])].to_numpy(float), axis=0)
        e = np.median(d, axis=0) if len(d) else np.full(2, np.nan)
        error = float(np.median(np.hypot(d[:, 0], d[:, 1]))) if len(d) else np.nan
        nees = float(np.mean((d**2 / var).sum(axis=1))) if len(d) else np.nan
        sigma = float(np.median(np.sqrt(var.sum(axis=1)))) if len(d) else np.nan
        verdict, scored_by, depth = "", "its rows", (place[2] - q[2] if len(place) > 2 else np.nan)
    fixes = outcome.estimates[outcome.estimates["estimator"] == "fix"][["x", "y"]].to_numpy(float)
    fixes = fixes[np.isfinite(fixes).all(axis=1)]
    return {"tag": tag, "kind": "reference", "truth": truth["truth"], "receiver": truth["receiver"],
            "truth_x_m": q[0], "truth_y_m": q[1], "truth_z_m": q[2], "truth_lat": truth["lat"],
            "truth_lon": truth["lon"], "x_m": place[0], "y_m": place[1], "z_m": place[2] if len(place) > 2 else np.nan,
            "error_m": error, "error_east_m": float(e[0]), "error_north_m": float(e[1]),
            "error_3d_m": float(np.hypot(error, depth)) if np.isfinite(depth) else np.nan, "sigma_m": sigma,
            "survey_sigma_m": truth["survey"], "nees": nees, "beyond_sigma": bool(nees > beyond()), "rows": rows,
            "flagged": flagged, "share_flagged": flagged / rows if rows else np.nan, "verdict": verdict,
            "scored_by": scored_by,
            "single_fix_median_error_m": float(np.median(np.linalg.norm(fixes - q[:2], axis=1))) if len(fixes)
            else np.nan, "receiver_persistent_m": np.nan, "in_sync": truth["in_sync"], "inside_array": None}


def _cross(summary: dict[str, Any], still: dict[str, Any], receiver: str, survey: float) -> np.ndarray | None:
    """The covariance (2, 2) [m²] of a reference tag's place with its deployment ``receiver``'s surveyed position
    (of error ``survey`` [m per axis]) where the tracker took that receiver's survey error too (its summary's
    ``survey_sigma_m``): one error, in the place and in the position scored against
    (:func:`~sblsim.models.tracking.still_tag.survey_cross`); None otherwise."""
    tracked = (summary.get("survey_sigma_m") or {}).get(receiver) if receiver and survey > 0 else None
    names = list(summary.get("receivers") or [])
    if not tracked or receiver not in names:
        return None
    return survey_cross(still, names.index(receiver), tracked * survey * np.eye(2))


def sync_rows(table: pd.DataFrame | None) -> list[dict[str, Any]]:
    """The sync tags' leave-one-out rows (the module docstring) from a synchronisation's ``sync_tags.csv`` table: each
    tag's one place where the table has it (``place_*``: :data:`~sblsim.orchestrator.sync.sync_tags.PLACE_COLUMNS`),
    else (a table written before places, or a place that could not be fitted) its single-emission fixes' median
    error, median σ and mean NEES."""
    if table is None or not len(table):
        return []
    out = []
    for r in table.to_dict("records"):
        heard, fixed = int(r["emissions"]), int(r["fixes"])
        x, y = float(r.get("truth_x_m", r["x_m"])), float(r.get("truth_y_m", r["y_m"]))
        row = {"tag": str(r["tag"]), "kind": "sync_left_out", "truth": f"its receiver {r['receiver']}'s position "
               "(the synchronisation's)", "receiver": str(r["receiver"]), "truth_x_m": x, "truth_y_m": y,
               "truth_z_m": np.nan, "truth_lat": np.nan, "truth_lon": np.nan, "x_m": float(r["median_x_m"]),
               "y_m": float(r["median_y_m"]), "z_m": np.nan, "error_m": float(r["median_error_m"]),
               "error_east_m": float(r["median_x_m"]) - x, "error_north_m": float(r["median_y_m"]) - y,
               "error_3d_m": np.nan, "sigma_m": float(r["median_sigma_m"]), "survey_sigma_m": np.nan,
               "nees": float(r["nees_mean"]), "beyond_sigma": None, "rows": heard, "flagged": heard - fixed,
               "share_flagged": (heard - fixed) / heard if heard else np.nan, "verdict": "",
               "single_fix_median_error_m": float(r["median_error_m"]), "receiver_persistent_m": np.nan,
               "in_sync": True, "inside_array": bool(r["inside_array"]), "scored_by": "single-emission fixes",
               "without_fix": heard - fixed}
        if np.isfinite(float(r.get("place_error_m", np.nan))):  # its one place, as a reference tag's
            px, py, rows, flagged = (float(r["place_x_m"]), float(r["place_y_m"]), int(r["place_rows"]),
                                     int(r["place_flagged"]))
            row |= {"x_m": px, "y_m": py, "error_m": float(r["place_error_m"]), "error_east_m": px - x,
                    "error_north_m": py - y, "sigma_m": float(r["place_sigma_m"]), "nees": float(r["place_nees"]),
                    "beyond_sigma": bool(float(r["place_nees"]) > beyond()), "rows": rows, "flagged": flagged,
                    "share_flagged": flagged / rows if rows else np.nan, "verdict": str(r["place_verdict"]),
                    "scored_by": "one place"}
        out.append(row)
    return out


def _pooled_references(rows: list[dict[str, Any]], terms: set[str]) -> dict[str, Any] | None:
    """The reference tags' pooled figures and what their σ holds."""
    if not rows:
        return None
    error = np.array([r["error_m"] for r in rows], float)
    nees = np.array([r["nees"] for r in rows], float)
    stated = [r for r in rows if np.isfinite(r["survey_sigma_m"])]
    held = sorted(terms) + ["the receivers' jackknife"]
    n = int(np.isfinite(nees).sum())
    return {"tags": len(rows), "median_error_m": float(np.nanmedian(error)),
            "nees_mean": float(np.nanmean(nees)) if n else None,
            "nees_consistent_90": consistent(n) if n else None,
            "rows": int(sum(r["rows"] for r in rows)), "flagged": int(sum(r["flagged"] for r in rows)),
            "beyond_sigma": [r["tag"] for r in rows if r["beyond_sigma"]], "beyond_nees": beyond(),
            "sigma_holds": f"each place's covariance as tracked (its pooled fit; {', '.join(held)})"
                           + (f"; the survey_sigma_m of {len(stated)} of {len(rows)}" if stated else "")
                           + ("" if len(stated) == len(rows) else
                              "; a position without survey_sigma_m taken as exact"),
            "survey_stated": len(stated)}


def _pooled_sync(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The sync tags' leave-one-out pooled: the median of the tags' errors, the mean NEES of those scored by their one
    place (with its 90 % interval), and as the synchronisation pools its single-emission fixes (the mean NEES of the
    tags inside the array)."""
    if not rows:
        return None
    placed = [r for r in rows if r["scored_by"] == "one place"]
    inside = [r["nees"] for r in rows if r["inside_array"] and r["scored_by"] != "one place"]
    return {"tags": len(rows), "median_error_m": float(np.median([r["error_m"] for r in rows])),
            "placed": len(placed), "nees_mean": float(np.mean([r["nees"] for r in placed])) if placed else None,
            "nees_consistent_90": consistent(len(placed)) if placed else None,
            "rows": int(sum(r["rows"] for r in placed)), "flagged": int(sum(r["flagged"] for r in placed)),
            "beyond_sigma": [r["tag"] for r in placed if r["beyond_sigma"]], "beyond_nees": beyond(),
            "nees_mean_inside": float(np.mean(inside)) if inside else None, "inside": len(inside),
            "emissions": int(sum(r["rows"] for r in rows if r["scored_by"] != "one place")),
            "without_fix": int(sum(r["without_fix"] for r in rows)),
            "figures": "each tag with the clocks fitted without its arrivals (sync_tags.csv): its one place from all "
                       "its emissions' arrivals, its own receiver's among them, as a reference tag's (the pooled fit, "
                       "the consider terms of the clocks' offsets and the survey, the receivers' jackknife), its error "
                       "from its receiver's position, sigma and NEES, its emissions flagged as moved; where no place, "
                       "its single-emission fixes from the other receivers (their median error, median sigma, mean "
                       "NEES: pooled over the tags inside the array). Pooled: the median of the tags' errors, the "
                       "mean NEES of the places"}


def _pooled_still(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """Every still tag scored by one place, reference tags and sync tags left out together: their count, median
    error, mean NEES and its 90 % interval (None where not both kinds have one)."""
    placed = [r for r in rows if r["scored_by"] == "one place"]
    nees = np.array([r["nees"] for r in placed], float)
    nees = nees[np.isfinite(nees)]
    if not len(nees) or len({r["kind"] for r in placed}) < 2:
        return None
    return {"tags": len(placed), "median_error_m": float(np.nanmedian([r["error_m"] for r in placed])),
            "nees_mean": float(np.mean(nees)), "nees_consistent_90": consistent(len(nees))}


def score(asked: Sequence[tuple[str, TagSpec]], tags: pd.DataFrame, outcomes: dict[str, Any],
          deployments: Deployments, synced=None, sync_dir: Path | None = None,
          survey_sigma: float | Mapping[str, float] | None = None) -> dict[str, Any]:
    """``study.json``'s ``reference_tags``: the reference tags and the sync tags left out in turn, per tag and pooled
    (the module docstring).

    Parameters
    ----------
    asked : sequence of (str, TagSpec)
        The tags asked for, by the name given.
    tags : pandas.DataFrame
        ``tags.csv`` (one row per tag asked for, in ``asked``'s order: ``tag``, ``status``, ``folder``).
    outcomes : dict
        Each tracked tag's :class:`~sblsim.orchestrator.tracks.outcome.TrackOutcome`, by its folder.
    deployments : Deployments
        The study's deployments (their positions in the frame: the positions scored against).
    synced : SyncOutcome, optional
        The synchronisation made here (its ``sync_tags`` and ``residuals``).
    sync_dir : Path, optional
        A synchronisation's folder given (its ``sync_tags.csv`` read, where it has one).
    survey_sigma : float or mapping, optional
        The receivers' survey error stated for the study [m per horizontal axis], one for all or each receiver's by
        its name (a study on refined positions: :func:`~.study_positions.position_sigmas`): the ``survey_sigma_m`` of
        each reference tag at a deployment whose sheet states none, and of the sync tags left out where the
        synchronisation made here took it (``synced.summary["survey_sigma_m"]``).

    Returns
    -------
    dict
        ``tags`` (rows of :data:`COLUMNS`), ``reference`` and ``sync_left_out`` (pooled; None where none),
        ``not_scored`` (each reference tag without a position or a track, with why), ``array_persistent_m`` (the
        median over the receivers of :func:`persistent_residual`), ``notes`` (a given synchronisation's
        ``sync_tags.csv`` refused: the tracks stand, its line said).
    """
    refs, missing, terms, homes = [], [], set(), []
    for (name, spec), row in zip(asked, tags.to_dict("records")):
        if spec.role != "reference":
            continue
        truth = truth_of(spec, deployments)
        if not isinstance(truth, str) and truth["receiver"] and not np.isfinite(truth["survey"]) \
                and survey_sigma is not None:  # at a surveyed deployment: the survey's stated error
            truth["survey"] = _each(survey_sigma, truth["receiver"])
        if isinstance(truth, str) or row["status"] != "tracked" or row["folder"] not in outcomes:
            missing.append({"tag": name, "why": truth if isinstance(truth, str) else f"not tracked ({row['reason']})"})
            continue
        outcome = outcomes[row["folder"]]
        refs.append(score_reference(str(row["tag"]), outcome, truth))
        terms |= set((outcome.summary.get("motion") or {}).get("consider_terms") or [])
        homes.append(truth["receiver"])
    # the residuals' pairs (a season's arrivals grouped) made where a reference tag is scored, not otherwise
    paired = None if synced is None or not refs else pairs(synced.residuals)
    for ref, home in zip(refs, homes) if paired is not None else ():
        if home:
            ref["receiver_persistent_m"] = persistent_residual(paired, home)
    notes = []
    try:
        table = synced.sync_tags if synced is not None else None if sync_dir is None else given_sync_tags(sync_dir)
    except ModelError as exc:  # the tracks stand: the sync tags' leave-one-out is not scored, said
        table = None
        notes.append(f"the sync tags' leave-one-out not scored: {exc}")
    loo = sync_rows(table)
    stated = None if synced is None else synced.summary.get("survey_sigma_m")
    for r in loo if stated is not None else ():  # their NEES holds the survey's stated error
        r["survey_sigma_m"] = _each(stated, r["receiver"])
    array = None
    if paired is not None and refs:  # the same figure at every receiver: its median
        values = [persistent_residual(paired, r) for r in paired["receiver"].unique()]
        array = float(np.nanmedian(values)) if np.isfinite(values).any() else None
    return {"tags": refs + loo, "reference": _pooled_references(refs, terms), "sync_left_out": _pooled_sync(loo),
            "still": _pooled_still(refs + loo), "not_scored": missing, "array_persistent_m": array, "notes": notes}


def _each(survey: float | Mapping[str, float], receiver: str) -> float:
    """The survey's error of ``receiver``'s position [m per axis]: one for all, or each receiver's (NaN where not
    named: taken as exact)."""
    if isinstance(survey, Mapping):
        return float(survey.get(receiver, np.nan))
    return float(survey)


def given_sync_tags(folder: Path) -> pd.DataFrame | None:
    """A given synchronisation's ``sync_tags.csv`` (the columns :func:`sync_rows` reads, each cell checked), None
    where the folder has none.

    Raises
    ------
    ModelError
        One line: a column missing, a cell outside its pattern or range.
    """
    path = _in_folder(Path(folder), "sync_tags.csv")
    if not path.exists():
        return None
    where = ("x_m", "y_m", "median_x_m", "median_y_m")
    figures = ("emissions", "fixes", "median_error_m", "median_sigma_m", "nees_mean")
    body, lines, name, col = _columns(path, "sync", ("tag", "receiver", *where, *figures, "inside_array"),
                                      "sblsim sync's sync_tags.csv", PLACE_COLUMNS)
    out = pd.DataFrame({"tag": pattern(body[col["tag"]], TRANSMITTER, "sync", name, lines, "tag", "a transmitter"),
                        "receiver": pattern(body[col["receiver"]], IDENTIFIER, "sync", name, lines, "receiver",
                                            "a receiver's serial")})
    for key in where:
        out[key] = numbers(body[col[key]], "sync", name, lines, key, -MAX_COORDINATE, MAX_COORDINATE, unit="m")
    for key in figures:
        out[key] = numbers(body[col[key]], "sync", name, lines, key, 0.0, 1e12)
    inside = pattern(body[col["inside_array"]], re.compile("(?i)true|false"), "sync", name, lines, "inside_array",
                     "True or False")
    out["inside_array"] = inside.str.lower() == "true"
    if not set(PLACE_COLUMNS) <= set(col):  # a table written before the places: its single-emission fixes scored
        return out
    for key in PLACE_COLUMNS[:-1]:  # each empty where no place was fitted
        low, high = (-MAX_COORDINATE, MAX_COORDINATE) if key in ("place_x_m", "place_y_m") else (0.0, 1e12)
        out[key] = numbers(body[col[key]], "sync", name, lines, key, low, high, missing=True)
    out["place_verdict"] = pattern(body[col["place_verdict"]], re.compile(r"[^\n]{0,300}"), "sync", name, lines,
                                   "place_verdict", "a line of at most 300 characters")
    return out


def table(summary: dict[str, Any] | None) -> pd.DataFrame:
    """``reference_tags.csv`` (:data:`COLUMNS`) from ``study.json``'s ``reference_tags``."""
    rows = [] if not summary else summary["tags"]
    return pd.DataFrame(rows, columns=list(COLUMNS))


__all__ = ["BEYOND_LEVEL", "COLUMNS", "beyond", "consistent", "given_sync_tags",
           "persistent_residual", "score", "score_reference", "sync_rows", "table", "truth_of"]
