"""``sblsim sync``'s ``sync_tags.csv``: each sync tag positioned emission by emission from the other receivers'
synchronised arrivals, with the clocks fitted without its arrivals (:func:`_fit_without`, leave-one-out), against its
known position (:func:`_sync_tags`; the fixes :func:`sblsim.models.sync.positions.position_emissions`'s), and placed
as the still tag it is, from all its arrivals (:func:`_still_place`, a reference tag's model:
:func:`sblsim.models.tracking.still_tag.still_tag`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
from scipy.spatial import Delaunay

from sblsim.models.declarations import ModelError
from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.clocks import Geometry, fit_clocks
from sblsim.models.sync.emissions import connected
from sblsim.models.sync.mean_offset import mean_offset_sigma
from sblsim.models.sync.positions import AMBIGUOUS, FAILED, UNCHECKED, position_emissions
from sblsim.models.sync.scale import SPEED_TOLERANCE
from sblsim.models.sync.season import clocks_in_windows
from sblsim.models.sync.windows import Windows
from sblsim.models.tracking.still_tag import place_score, still_tag, survey_cross
from sblsim.orchestrator.io.memory import release
from sblsim.orchestrator.sync import segments

#: ``sync_tags.csv``'s columns of each left-out sync tag's one place (:func:`_still_place`): ``place_x_m``,
#: ``place_y_m`` [m], its error from its receiver's position and σ (the 2-D covariance with that position's, root
#: trace) [m], its 2-D NEES, its emissions placed and those flagged as moved, and the still tag's verdict.
PLACE_COLUMNS = ("place_x_m", "place_y_m", "place_error_m", "place_sigma_m", "place_nees", "place_rows",
                 "place_flagged", "place_verdict")


def _sync_tags(fit: ClockFit, receiver, tag, emission, time, distance, slowness, used, linked, start, width,
               positions, tag_names, tag_home, names, leave_one_out: bool, notes: list[str],
               geometry: Geometry | None = None, clock: np.ndarray | None = None,
               site: np.ndarray | None = None, fits: dict | None = None,
               table_sigma: float | np.ndarray | None = None, windows: Windows | None = None,
               rounding: np.ndarray | None = None) -> pd.DataFrame:
    """``sync_tags.csv``: each sync tag positioned emission by emission from the other receivers' synchronised
    arrivals (its own receiver left out), with the clocks fitted without its arrivals (``leave_one_out``), against
    its known position: the table's, or with ``geometry`` its receiver's position refined without the tag's
    arrivals (``truth_x_m``, ``truth_y_m``, its sigma ``truth_sigma_m``; the NEES with the fix's covariance and
    that position's summed: two estimates from disjoint arrivals), the error against the table beside it
    (``table_error_m``).

    Each fix is robust and checked (:func:`~sblsim.models.sync.positions.position_emissions`): the statistics are
    over the trusted fixes (``fixes``); ``fixes_unchecked`` (no redundancy: the arrivals fitted exactly, nothing to
    check them), ``fixes_failed`` (the overall test failed with a redundancy of 1: an outlier not identifiable) and
    ``fixes_ambiguous`` (a rejected arrival could be swapped for a kept one) are counted beside them,
    ``fixes_scaled`` the fixes whose covariance the a-posteriori variance factor scaled, ``arrivals_rejected`` the
    arrivals the trusted fixes rejected, ``median_redundancy`` theirs. The clock fit's own rejections of the tag's
    arrivals are not carried into its fixes: that fit saw the tag at its known
    position, so its rejections would use the position the fixes are checked against.

    Where a receiver's clock broke, ``clock`` (n,) is each arrival's clock row and ``site`` each row's receiver
    (:func:`~sblsim.orchestrator.sync.segments.clock_rows`), ``linked`` per clock row. ``fits``: the fits without
    each tag already made (:func:`_fit_without`, by tag). ``table_sigma`` [m]: without ``geometry``, the table's
    horizontal sigma per axis (one, or each receiver's (R,)), summed into the NEES's covariance (the survey's stated
    error) and a consider term of each place. ``windows``: the
    season's clocks were fitted in these windows (:mod:`sblsim.models.sync.windows`), and so is each fit without a
    tag. ``rounding`` (R,) [s]: each receiver's times' rounding σ, a slow error of each place's verdict (None:
    none)."""
    dim = positions.shape[1]
    rows = []
    c = receiver if clock is None else clock
    steady = None if site is None or len(site) == len(names) else site == start
    knot_sigma = segments.receiver_sigmas(fit, len(names))
    for i, name in enumerate(tag_names):
        home = tag_home[i]
        own = (tag == i) & used & linked[c]  # its arrivals, its own receiver's among them
        mine = own & (receiver != home)
        if mine.sum() < dim + 2:
            continue
        this = fit
        release()  # the last tag's freed buffers back to the system, not kept tag after tag
        if leave_one_out:
            got = fits[i] if fits is not None and i in fits else _fit_without(
                i, fit, c, tag, emission, time, distance, slowness, used, start, width, len(linked), geometry,
                None if clock is None else site, steady, windows)
            if got is None:
                notes.append(f"sync tag {name}: the clocks cannot be fitted without it; not positioned")
                continue
            this, still = got
            mine &= still[c]
            own &= still[c]
        rows_e = np.flatnonzero(mine)
        ems, local = np.unique(emission[rows_e], return_inverse=True)
        arrival = np.full((len(ems), len(names)), np.nan)
        arrival[local, receiver[rows_e]] = time[rows_e] - this.offset(c[rows_e], time[rows_e])
        s = np.full(len(ems), this.slowness if slowness is None else np.nan)
        if slowness is not None:
            s = np.bincount(local, slowness[rows_e]) / np.bincount(local)
        white = segments.receiver_values(np.where(np.isfinite(this.scale), this.scale, 1e-3), fit, len(names))
        known = np.isfinite(knot_sigma)
        offset_sigma = np.array([np.median(knot_sigma[j][known[j]]) if known[j].any() else 0.0
                                 for j in range(len(names))])
        sigma = np.sqrt(white ** 2 + offset_sigma ** 2)
        where = positions
        truth_cov = np.zeros((dim, dim))
        survey = None if table_sigma is None else np.broadcast_to(np.asarray(table_sigma, float), (len(names),))
        if geometry is None and table_sigma is not None:
            truth_cov[:2, :2] = survey[home] ** 2 * np.eye(2)
        if geometry is not None:  # the receivers where the fit without this tag puts them
            where = positions.copy()
            where[:, :2] += this.shift
            truth_cov[:2, :2] = this.shift_covariance[home]
            survey = np.sqrt(np.trace(this.shift_covariance, axis1=1, axis2=2) / 2)
            sigma = np.sqrt(sigma ** 2 + (np.nanmedian(s) * survey) ** 2)
        fixes = position_emissions(arrival, where, sigma, s)
        ok = fixes.ok
        if not ok.any():
            continue
        truth = where[home]
        error = fixes.position[ok] - truth
        error_m = np.linalg.norm(error, axis=1)
        own_sigma = np.sqrt(np.trace(fixes.covariance[ok], axis1=1, axis2=2))
        nees = np.einsum("ek,ekl,el->e", error, np.linalg.inv(fixes.covariance[ok] + truth_cov), error)
        heard = np.flatnonzero(fixes.used[ok].any(axis=0))
        mean = np.median(fixes.position[ok], axis=0)
        rows.append({"tag": name, "receiver": names[home], "x_m": truth[0], "y_m": truth[1],
                     "emissions": len(ems), "fixes": int(ok.sum()), "receivers_used": len(heard),
                     "median_error_m": float(np.median(error_m)), "median_sigma_m": float(np.median(own_sigma)),
                     "rms_error_m": float(np.sqrt(np.mean(error_m ** 2))),
                     "p90_error_m": float(np.percentile(error_m, 90)), "nees_mean": float(np.mean(nees)),
                     "nees_median": float(np.median(nees)), "median_x_m": mean[0], "median_y_m": mean[1],
                     "median_position_error_m": float(np.linalg.norm(mean - truth)),
                     "inside_array": _inside(truth, where[heard]), "leave_one_out": leave_one_out})
        if geometry is not None:
            rows[-1].update({"x_m": positions[home, 0], "y_m": positions[home, 1], "truth_x_m": truth[0],
                             "truth_y_m": truth[1], "truth_sigma_m": float(np.sqrt(np.trace(truth_cov))),
                             "table_error_m": float(np.median(np.linalg.norm(fixes.position[ok] - positions[home],
                                                                             axis=1)))})
        if leave_one_out:  # (else the clocks were fitted with its arrivals: its place is no check)
            at_home = np.flatnonzero(own & (receiver == home))
            k = np.searchsorted(ems, emission[at_home])
            found = k < len(ems)
            found[found] = ems[k[found]] == emission[at_home[found]]
            arrival[k[found], home] = time[at_home[found]] - this.offset(c[at_home[found]], time[at_home[found]])
            held = _averaged_clocks(fit, knot_sigma, offset_sigma, receiver[own], time[own])
            rows[-1].update(_still_place(arrival, where, 1.0 / float(np.nanmedian(s)), fixes, white,
                                         (offset_sigma, held), survey, truth, truth_cov, home, rounding))
        rows[-1].update({"fixes_unchecked": int((fixes.status == UNCHECKED).sum()),
                         "fixes_failed": int((fixes.status == FAILED).sum()),
                         "fixes_ambiguous": int((fixes.status == AMBIGUOUS).sum()),
                         "fixes_scaled": int((fixes.variance_factor[ok] > 1).sum()),
                         "arrivals_rejected": int(fixes.rejected[ok].sum()),
                         "median_redundancy": float(np.median(fixes.redundancy[ok]))})
    columns = ["tag", "receiver", "x_m", "y_m", "emissions", "fixes", "receivers_used", "median_error_m",
               "median_sigma_m", "rms_error_m", "p90_error_m", "nees_mean", "nees_median", "median_x_m", "median_y_m",
               "median_position_error_m", "inside_array", "leave_one_out"]
    if geometry is not None:
        columns += ["truth_x_m", "truth_y_m", "truth_sigma_m", "table_error_m"]
    columns += ["fixes_unchecked", "fixes_failed", "fixes_ambiguous", "fixes_scaled", "arrivals_rejected",
                "median_redundancy", *PLACE_COLUMNS]
    return pd.DataFrame(rows, columns=columns)


def _averaged_clocks(fit: ClockFit, knot_sigma: np.ndarray, each: np.ndarray, receiver: np.ndarray,
                     time: np.ndarray) -> np.ndarray:
    """Each receiver's clock offset error (R,) [s] averaged over a still tag's arrivals at it (``receiver`` (n,),
    ``time`` (n,) [s] on the fit's base: :func:`~sblsim.models.sync.mean_offset.mean_offset_sigma` of its edges'
    ``knot_sigma`` (R, K + 1) and its bins' drifts' σ), the bias its pooled place takes of it; ``each`` (R,) [s]
    (one edge's) where its clock broke (a row per segment), the tag has no arrival there, or an edge its arrivals
    lean on has no σ."""
    out = np.array(each, float)
    if fit.site is not None:
        return out
    for j in np.unique(receiver):
        mean = mean_offset_sigma(knot_sigma[j], fit.drift_sigma[j], fit.edges, time[receiver == j])
        out[j] = mean if np.isfinite(mean) else out[j]  # (an edge it leans on without a σ: one edge's)
    return out


def _still_place(arrival: np.ndarray, where: np.ndarray, c: float, fixes, white: np.ndarray,
                 clock: tuple[np.ndarray, np.ndarray], survey: np.ndarray | None, truth: np.ndarray,
                 truth_cov: np.ndarray, home: int, rounding: np.ndarray | None = None) -> dict:
    """A left-out sync tag scored as the still tag it is, as a reference tag is (:data:`PLACE_COLUMNS`): its one
    place from its emissions' arrivals (E, R) [s] (its own receiver's too: the clocks were fitted without any of
    them), synchronised by the clocks fitted without it (:func:`~sblsim.models.tracking.still_tag.still_tag`:
    the pooled fit of the receivers' timing noise ``white`` (R,) [s], the consider terms of the errors pooling does
    not average, each receiver's clock offset's sigma ``clock`` (R,) [s] (at a ping, for the verdict; averaged over
    the tag's arrivals, for the place: a pair) and position's ``survey`` (R,) [m per axis; None: exact], and the
    receivers' jackknife; the emissions that moved beyond what those errors let its
    single-emission ``fixes`` (:func:`position_emissions`', without its own receiver) wander flagged), against
    ``truth`` (dim,) [m] of covariance ``truth_cov`` [m²], its receiver ``home``'s position: the 2-D NEES
    ``eᵀ (P + Q − X − Xᵀ)⁻¹ e``, ``X`` what that receiver's survey error moved the place by with it
    (:func:`~sblsim.models.tracking.still_tag.survey_cross`, where a survey error is stated); ``c`` [m/s];
    ``rounding`` (R,) [s] the receivers' times' rounding σ (the verdict's). NaN where the place cannot be fitted (too
    few receivers: the reason in ``place_verdict``)."""
    try:
        still = still_tag(arrival, where, c, (fixes.position, fixes.emission_time, fixes.covariance, fixes.used),
                          fixes.ok, white, survey, {}, *clock, rounding=rounding)
    except ModelError as exc:
        return dict.fromkeys(PLACE_COLUMNS, np.nan) | {"place_verdict": str(exc)}
    summary = still.summary["still"]
    cross = None if survey is None else survey_cross(summary, home, truth_cov[:2, :2])
    _, error, sigma, nees = place_score(summary, truth, truth_cov[:2, :2], cross)
    return {"place_x_m": summary["place"][0], "place_y_m": summary["place"][1], "place_error_m": error,
            "place_sigma_m": sigma, "place_nees": nees, "place_rows": len(still.pings),
            "place_flagged": int(still.moved.sum()), "place_verdict": summary["verdict"]}


def _fit_without(i: int, fit: ClockFit, c, tag, emission, time, distance, slowness, used, start, width, n_rows: int,
                 geometry: Geometry | None, site, steady, windows: Windows | None = None
                 ) -> tuple[ClockFit, np.ndarray] | None:
    """The clocks fitted without sync tag ``i``'s arrivals (the kept arrivals and scales of ``fit``; with
    ``geometry`` the positions refined from ``fit``'s) and the clock rows still synchronised; None where they
    cannot be fitted without it. Where the sound speed is estimated and the fit without the tag puts it more than
    :data:`~sblsim.models.sync.scale.SPEED_TOLERANCE` from ``fit``'s (the other sync tags cannot tell it), it is
    fitted again with ``fit``'s held."""
    without = used & (tag != i)
    still = connected(c[without], emission[without], n_rows, start)
    loo = None if geometry is None else Geometry(geometry.source, geometry.positions, geometry.sigma, fit.shift, site)

    def refit(given):
        if windows is not None:  # (positions fixed: the windows' fits are made without geometry)
            # (its clocks alone: the refit's residuals are never read, and a season's of them not held)
            return clocks_in_windows(windows, c, emission, time, distance, given, without, still, start, width,
                                     fit.kept, fit.scale, steady, arrivals=False)
        return fit_clocks(c, emission, time, distance, given, without, still, start, width, keep=fit.kept,
                          scale=fit.scale, sigmas=False, geometry=loo, steady=steady)

    try:
        this = refit(slowness)
        estimated = slowness is None and fit.slowness is not None
        if estimated and not (this.slowness and abs(fit.slowness / this.slowness - 1.0) <= SPEED_TOLERANCE):
            # the sound speed the other sync tags cannot tell (on 16 receivers with 3 sync tags, 0.035 m/s without
            # one of them: its fixes 269 m off with a σ of 17 µm): the full fit's held
            this = replace(refit(np.full(len(time), fit.slowness)), slowness=fit.slowness,
                           slowness_sigma=fit.slowness_sigma)
    except ModelError:
        return None
    return this, still


def _inside(point: np.ndarray, points: np.ndarray) -> bool:
    """Whether ``point`` is inside the convex hull of ``points`` (horizontally)."""
    try:
        return bool(Delaunay(points[:, :2]).find_simplex(point[:2]) >= 0)
    except Exception:  # fewer than three points, or all on a line
        return False
