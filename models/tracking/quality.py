"""Never silently lost: a track checked against its own data, each ping marked ``ok``, ``restart`` or ``flagged``.

A tracker that has lost its target still writes positions, often with small covariances. Each estimate is therefore
checked against what the same data say without the motion model:

* the **trusted single-ping fixes**: a fix of dim + 2 receivers or more (one redundant arrival at least; a depth
  the fix was given, a reading or a prior, counts as one more, as the fix counts it) that kept every arrival of its
  ping or still has dim + 3, passed its own χ² test, and whose DRMS is at most
  :data:`TRUSTED_FIX_DRMS`. At a ping with such a fix, the track agrees with it when it lies within the χ² gate
  :data:`FIX_GATE` of it against the two covariances summed (Bar-Shalom, Li & Kirubarajan, *Estimation with
  Applications to Tracking and Navigation*, Wiley 2001, § 5.4: the normalised distance of two independent estimates
  of one quantity), or within :data:`FIX_SLACK` (a multipath arrival the fix kept moves it by metres, where the two
  covariances are of decimetres). Where they disagree, the one more of the ping's arrivals agree with
  (:func:`explained`) is taken as right: the track is off at that ping when the fix explains more arrivals than the
  track, else the fix is off (a multipath arrival it kept). An estimate its own measurements do not check (none to
  spare, below) agrees with no fix beyond :data:`FIX_SLACK`, however large its covariance, and is flagged there on
  its own. A fix that one faulty arrival could have put as far from the estimate as it is, unseen by its own χ² test
  (its horizontal protection level: :mod:`sblsim.models.tracking.integrity`), refutes nothing there: a fix of dim + 2
  arrivals in a weak geometry absorbs a reflection by tens of metres with a χ² that passes, and explains the
  reflection with the rest;
* one ping where the track is off, between pings where it agrees, may be multipath the fix and the track read
  differently: from two successive trusted fixes where the track is off, with no agreeing fix between, the whole
  stretch is lost (to the end of the record where no agreeing fix follows, from its start where none precedes);
* at a ping without a trusted fix, the track must be reachable from the nearest trusted fixes before or after it:
  within the gate's radius plus :data:`MAX_SPEED` times the time between (a tag does not outrun that);
* the **physical speed** between successive estimates: at most :data:`MAX_SPEED` beyond their own uncertainty;
* the estimate's **own uncertainty**: its horizontal DRMS (√ of the trace of its 2×2 position covariance as
  reported, with the errors common to the track and its fixes in it: the receivers' survey, the sound speed) at most
  :data:`TRUSTED_FIX_DRMS`, the limit a trusted fix must meet. One limit for both: a row is ``ok`` only where it is
  placed at least as well as a fix the checks trust. A row the arrivals cannot place (a ping heard by one receiver
  or none, held only by the motion model) is not a position a user should take as good, however near its neighbours
  it is; a covariance that is not finite says nothing of where the row is, and fails too;
* a row its own measurements do not check: fewer than dim + 2 agree with it (the arrivals within
  :data:`EXPLAINED_SIGMAS` of it, and a depth it was given counted as one more, as a trusted fix counts it), none
  to spare beyond its position's dim coordinates and its emission time. With dim + 1 they are fitted exactly
  whatever one of them is (a reflection moves the row by metres to tens of metres and nothing in its ping says
  so), with fewer they do not place it. Such a row is **unverified** where the motion model alone, from the
  nearest trusted fix, would not place it within the same limit, ``√(DRMS_fix² + 2 q τ³ / 3) >
  TRUSTED_FIX_DRMS`` with τ the time to that fix and q the motion model's acceleration PSD (the
  white-noise-acceleration model's position variance per axis, q τ³ / 3: Bar-Shalom, Li & Kirubarajan 2001,
  § 6.2.2). Between trusted fixes a chain of such rows can settle on a wrong branch of each ping's hyperbola (a
  thin array's pings heard by two receivers), or on a reflection that pings of three receivers fit exactly, with
  a small covariance of its own: nothing in the data checks it there.

Another estimator of the same pings (a filter, the RTS smoother, the single-ping fixes beside the robust smoother's
track) is checked against the **track** too (:func:`off_the_track`): where the track's row is ``ok`` and the two
disagree beyond the χ² gate :data:`FIX_GATE` of their own covariances summed (the errors common to both, the survey's
and the sound speed's, left out), the one that explains fewer of the ping's arrivals is off; the track, which passed
every check above, is kept where they tie, and where the other row's own arrivals do not check it (none to spare: its
dim + 1 arrivals are fitted exactly, a reflection among them too, so that it explains them all; or, a single-ping
fix, one faulty arrival could have put it as far from the track unseen). A filter that kept
a reflection is metres off with a covariance of decimetres, and nothing else in its ping says so.

A ping that fails is ``flagged``; a ping where a filter started again (a restart, a new segment after a gap) is
``restart``; the rest ``ok``. A track kilometres from every fix is never ``ok``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

#: χ²(2) at 1 − 10⁻⁴: the gate of a track against a trusted fix (2-D, the horizontal position).
FIX_GATE = 18.42
#: A track within this distance of a trusted fix agrees with it, whatever their covariances [m].
FIX_SLACK = 5.0
#: The largest DRMS of a trusted single-ping fix, and of an estimate marked ``ok`` (its own covariance's) [m].
TRUSTED_FIX_DRMS = 10.0
#: The fastest a tracked tag moves [m/s] (a towed pinger, a fish's burst; a limit, not a typical speed).
MAX_SPEED = 10.0
#: An arrival agrees with a position when its time, less the travel time from there, is within this many standard
#: deviations of a time of arrival of the median over the ping's arrivals (the robust smoother's weight of 0.1 at
#: ν = 3, :data:`~sblsim.models.tracking.smoother.ROBUST_KEPT_WEIGHT`).
EXPLAINED_SIGMAS = 6.1
#: The quality marks, in order of severity.
QUALITY = ("ok", "restart", "flagged")
#: The reasons of a flag, in the order a row's ``quality_reason`` lists them: each :class:`Quality` field and the
#: reason's name in the tables (module docstring).
REASONS = (("stretch", "off_trusted_fixes"), ("alone", "off_a_trusted_fix"), ("reach", "out_of_reach"),
           ("speed", "too_fast"), ("uncertain", "placed_less_well_than_a_fix"), ("unverified", "unverified"),
           ("unplaced", "no_position"), ("track", "off_the_track"))


@dataclass(frozen=True)
class Quality:
    """What :func:`check_track` returns for m pings: ``quality`` (m,) of str (:data:`QUALITY`), and per ping as bool
    (m,) arrays: ``fix`` (outside its own trusted fix: not flagged alone), and the reasons of a flag, ``stretch``
    (from one such ping to the next with no agreeing fix between), ``reach`` (out of reach of the nearest trusted
    fixes), ``speed`` (a jump faster than :data:`MAX_SPEED`), ``uncertain`` (a horizontal DRMS of its own above
    :data:`TRUSTED_FIX_DRMS`, or not finite), ``unverified`` (not checked by its own measurements and beyond the motion
    model's reach of a trusted fix: module docstring), ``alone`` (off a trusted fix that explains more of its ping's
    arrivals, its own measurements not checking it), ``unplaced`` (no finite position), ``track`` (another
    estimator's row off the track's, :func:`off_the_track`; None where not checked). A flagged row has one of these
    reasons at least (:attr:`reason`)."""

    quality: np.ndarray
    fix: np.ndarray
    stretch: np.ndarray
    reach: np.ndarray
    speed: np.ndarray
    uncertain: np.ndarray
    unverified: np.ndarray
    alone: np.ndarray
    unplaced: np.ndarray
    track: np.ndarray | None = None

    @property
    def flagged(self) -> int:
        """The pings flagged."""
        return int((self.quality == "flagged").sum())

    @property
    def reason(self) -> np.ndarray:
        """(m,) of str: each flagged row's reasons (:data:`REASONS`' names, joined by ``;``), ``""`` for a row not
        flagged."""
        return reasons(self.quality == "flagged", {name: getattr(self, field) for field, name in REASONS
                                                   if getattr(self, field) is not None})


def reasons(flagged: np.ndarray, why: dict[str, np.ndarray]) -> np.ndarray:
    """Each flagged row's reasons joined by ``;`` in the order of ``why`` (``""`` where not flagged).

    Parameters
    ----------
    flagged : ndarray of bool, (m,)
    why : dict
        A reason's name -> (m,) bool, the rows it holds for.

    Returns
    -------
    ndarray of str, (m,)
    """
    out = np.full(len(flagged), "", dtype=object)
    for name, holds in why.items():
        at = np.asarray(flagged, bool) & np.asarray(holds, bool)
        out[at] = np.where(out[at] == "", name, out[at] + ";" + name)
    return out.astype(str)


def _to_spare(count: np.ndarray, known_depth: np.ndarray | None, dim: int) -> np.ndarray:
    """The measurements of each ping beyond the dim + 1 that fit a position and emission time exactly: its ``count``
    (m,) arrivals, and a depth it was given (``known_depth`` (m,) bool: a reading, a depth given or a prior) as one
    more."""
    return count + (0 if known_depth is None else np.asarray(known_depth, bool)) - (dim + 1)


def trusted_fixes(positions: np.ndarray, covariances: np.ndarray, used: np.ndarray, heard: np.ndarray,
                  chi2: np.ndarray, dim: int, known_depth: np.ndarray | None = None) -> np.ndarray:
    """Which single-ping fixes are trusted (module docstring).

    Parameters
    ----------
    positions : ndarray, (m, dim)
        The fixes [m], NaN where none.
    covariances : ndarray, (m, ≥dim, ≥dim)
        Their covariances [m²] (the position block first).
    used : ndarray, (m,)
        The arrivals each fix kept.
    heard : ndarray, (m,)
        The arrivals of each ping.
    chi2 : ndarray, (m,)
        Each fix's sum of squared normalised residuals.
    dim : int
    known_depth : ndarray of bool, (m,), optional
        The pings whose depth was one more measurement of the fix (a depth-sensor reading, a depth given or a prior:
        :func:`~sblsim.models.tracking.fix.fix_pings`): counted with its arrivals, as the fix counts it.

    Returns
    -------
    ndarray of bool, (m,)
    """
    from scipy.stats import chi2 as chi2_dist

    used, heard = np.asarray(used), np.asarray(heard)
    spare = _to_spare(used, known_depth, dim)
    finite = np.isfinite(positions).all(axis=1) & np.isfinite(chi2)
    redundant = (spare >= 1) & ((used == heard) | (spare >= 2))
    dof = np.maximum(spare, 1)
    passes = np.where(finite, chi2, np.inf) <= chi2_dist.ppf(0.999, dof)
    with np.errstate(invalid="ignore"):
        spread = np.sqrt(np.trace(covariances[:, :dim, :dim], axis1=1, axis2=2))
    return finite & redundant & passes & (np.nan_to_num(spread, nan=np.inf) <= TRUSTED_FIX_DRMS)


def explained(toa: np.ndarray, receivers: np.ndarray, positions: np.ndarray, c: float,
              sigma_toa: float | np.ndarray) -> np.ndarray:
    """How many of each ping's arrivals agree with a position (module docstring).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        [m].
    positions : ndarray, (m, dim)
        The positions to test [m] (NaN: none agree).
    c : float
        Sound speed [m/s].
    sigma_toa : float or ndarray, (n,)
        [s]: one, or each receiver's.

    Returns
    -------
    ndarray of int, (m,)
    """
    toa = np.asarray(toa, float)
    d = np.linalg.norm(np.asarray(positions, float)[:, None, :] - np.asarray(receivers, float)[None], axis=2)
    emitted = toa - d / c
    heard = np.isfinite(emitted)
    out = np.zeros(len(toa), int)
    rows = heard.any(axis=1)
    if rows.any():
        centre = np.nanmedian(emitted[rows], axis=1)
        out[rows] = (np.abs(emitted[rows] - centre[:, None]) <= EXPLAINED_SIGMAS * sigma_toa).sum(axis=1)
    return out


def _distance2(e: np.ndarray, C: np.ndarray) -> np.ndarray:
    """``eᵀ C⁻¹ e`` per row of e (k, 2) and C (k, 2, 2); inf where C is singular."""
    det = C[:, 0, 0] * C[:, 1, 1] - C[:, 0, 1] * C[:, 1, 0]
    num = C[:, 1, 1] * e[:, 0] ** 2 - (C[:, 0, 1] + C[:, 1, 0]) * e[:, 0] * e[:, 1] + C[:, 0, 0] * e[:, 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(det > 0, num / det, np.inf)


def check_track(times: np.ndarray, positions: np.ndarray, covariances: np.ndarray, fixes: np.ndarray,
                fix_covariances: np.ndarray, trusted: np.ndarray, restarts: np.ndarray | None = None,
                max_speed: float = MAX_SPEED, explained: np.ndarray | None = None,
                fix_used: np.ndarray | None = None, reported: np.ndarray | None = None,
                acceleration_psd: float | None = None, known_depth: np.ndarray | None = None,
                fix_protection: np.ndarray | None = None) -> Quality:
    """Each estimate of a track checked against the trusted single-ping fixes, the physical speed and its own
    uncertainty (module docstring), on the horizontal position.

    Parameters
    ----------
    times : ndarray, (m,)
        The estimates' emission times [s], increasing.
    positions : ndarray, (m, dim)
        The estimates [m], dim 2 or 3 (the checks take the horizontal position; dim decides how many measurements
        check an estimate).
    covariances : ndarray, (m, ≥2, ≥2)
        Their covariances [m²].
    fixes : ndarray, (m, ≥2)
        The single-ping fixes of the same pings [m], NaN where none.
    fix_covariances : ndarray, (m, ≥2, ≥2)
        Their covariances [m²].
    trusted : ndarray of bool, (m,)
        Which fixes are trusted (:func:`trusted_fixes`).
    restarts : ndarray of bool, (m,), optional
        Where the estimator started again (``restart`` unless flagged).
    max_speed : float
        [m/s].
    explained, fix_used : ndarray, (m,), optional
        The arrivals that agree with the estimate and with the fix at each ping (:func:`explained`); without them a
        disagreeing fix counts against the track.
    reported : ndarray, (m, ≥2, ≥2), optional
        The covariances the estimates are reported with [m²], where they hold errors common to the track and its
        fixes (the receivers' survey, the sound speed: consider terms): the own-uncertainty limit takes these (a
        row that error leaves unplaced is not ``ok``), the fixes' gates ``covariances`` (default: ``covariances``).
    acceleration_psd : float, optional
        The motion model's q [m²/s³]: with ``explained``, a row its own measurements do not check is ``unverified``
        beyond the motion model's reach of the nearest trusted fix (module docstring); without it, not checked (a
        tag that does not move).
    known_depth : ndarray of bool, (m,), optional
        The estimates that were given the tag's depth (a depth-sensor reading, a depth given or a prior): one more
        measurement beside the arrivals that agree with them, as :func:`trusted_fixes` counts it. An estimate's own
        measurements check it with dim + 2 (one to spare, as a trusted fix's): in 3-D five arrivals, or four and
        its depth; in 2-D four arrivals. Default: none given.
    fix_protection : ndarray, (m,), optional
        Each fix's horizontal protection level [m] (:func:`~sblsim.models.tracking.integrity.protection_levels`): a
        fix that one faulty arrival could have put as far from the estimate as it is, unseen by its own test, does
        not count against it (NaN: not assessed, it counts). Default: every disagreeing fix counts.

    Returns
    -------
    Quality
    """
    t = np.asarray(times, float)
    dim = np.asarray(positions).shape[1]
    p = np.asarray(positions, float)[:, :2]
    P = np.asarray(covariances, float)[:, :2, :2]
    m = len(t)
    fx, C = np.asarray(fixes, float)[:, :2], np.asarray(fix_covariances, float)[:, :2, :2]
    trusted = np.asarray(trusted, bool) & np.isfinite(fx).all(axis=1)
    # the estimate's own horizontal DRMS: above a trusted fix's limit (or not finite), the row is not placed
    R = P if reported is None else np.asarray(reported, float)[:, :2, :2]
    with np.errstate(invalid="ignore"):
        drms = np.sqrt(R[:, 0, 0] + R[:, 1, 1])
    uncertain = ~(drms <= TRUSTED_FIX_DRMS) | ~np.isfinite(R).all(axis=(1, 2))
    P = np.where(np.isfinite(P), P, 0.0)
    fix_bad = np.zeros(m, bool)
    # the measurements that agree with the estimate have none to spare: they do not check it
    unchecked = None if explained is None else _to_spare(np.asarray(explained), known_depth, dim) < 1
    alone = np.zeros(m, bool)  # off a trusted fix while its own measurements do not check it
    k = np.flatnonzero(trusted)
    if len(k):
        d2 = _distance2(p[k] - fx[k], P[k] + C[k])
        apart = np.linalg.norm(p[k] - fx[k], axis=1)
        near = apart <= FIX_SLACK
        if fix_protection is not None:  # a fix one reflection could have put there unseen refutes nothing there
            near |= np.asarray(fix_protection, float)[k] >= apart
        fix_bad[k] = ~((d2 <= FIX_GATE) | near)
        if explained is not None and fix_used is not None:
            ours, theirs = np.asarray(explained)[k], np.asarray(fix_used)[k]
            # an estimate its own measurements do not check agrees with nothing beyond the slack, however large its
            # covariance, where the fix explains more of the ping's arrivals
            blind = unchecked[k] & ~near
            fix_more = theirs > ours
            fix_bad[k] = (fix_bad[k] | blind) & fix_more
            alone[k] = blind & fix_more
    # a stretch between two disagreeing trusted fixes with no agreeing one between
    stretch = np.zeros(m, bool)
    bad_runs = fix_bad[k]
    for j in np.flatnonzero(bad_runs[:-1] & bad_runs[1:]):
        stretch[k[j]:k[j + 1] + 1] = True
    if len(k) >= 2:  # a run of off pings at either end: lost to the end (no agreeing fix to come back to)
        if bad_runs[-1] and bad_runs[-2]:
            stretch[k[-1]:] = True
        if bad_runs[0] and bad_runs[1]:
            stretch[:k[0] + 1] = True
    # out of reach of the nearest trusted fixes before and after
    reach = np.zeros(m, bool)
    if len(k):  # each row's trusted fixes before and after it (out of range where there is none)
        before = np.searchsorted(k, np.arange(m), side="right") - 1
        after = np.searchsorted(k, np.arange(m), side="left")
        ok_any = np.zeros(m, bool)
        has_any = np.zeros(m, bool)
        for side in (before, after):
            valid = (side >= 0) & (side < len(k))
            j = k[np.clip(side, 0, len(k) - 1)]
            spread = np.sqrt(np.clip(np.linalg.eigvalsh(P + C[j])[:, -1], 0, None))
            dist = np.linalg.norm(p - fx[j], axis=1)
            ok_any |= valid & (dist <= np.sqrt(FIX_GATE) * spread + max_speed * np.abs(t - t[j]))
            has_any |= valid
        reach = has_any & ~ok_any & ~trusted
    # the physical speed between successive estimates
    speed = np.zeros(m, bool)
    if m > 1:
        dt = np.diff(t)
        step = np.linalg.norm(np.diff(p, axis=0), axis=1)
        slack = 3.0 * np.sqrt(np.trace(P[1:], axis1=1, axis2=2) + np.trace(P[:-1], axis1=1, axis2=2))
        with np.errstate(divide="ignore", invalid="ignore"):
            fast = ~(step <= max_speed * np.abs(dt) + slack)
        speed[1:] |= fast
        speed[:-1] |= fast
    # a row its own measurements do not check, held by the motion model beyond its reach of a trusted fix
    unverified = np.zeros(m, bool)
    if acceleration_psd is not None and explained is not None:
        unverified = unchecked & ~trusted  # (as ``blind`` above)
        if len(k):  # the nearer of the trusted fixes before and after (reach's)
            lo, hi = k[np.clip(before, 0, len(k) - 1)], k[np.clip(after, 0, len(k) - 1)]
            near = np.where(np.abs(t - t[lo]) <= np.abs(t[hi] - t), lo, hi)
            placed2 = np.trace(C[near], axis1=1, axis2=2) + 2.0 * acceleration_psd * np.abs(t - t[near]) ** 3 / 3.0
            unverified &= ~(placed2 <= TRUSTED_FIX_DRMS ** 2)
    finite = np.isfinite(p).all(axis=1)
    flagged = stretch | alone | reach | speed | uncertain | unverified | ~finite
    quality = np.full(m, "ok", dtype=object)
    if restarts is not None:
        quality[np.asarray(restarts, bool)] = "restart"
    quality[flagged] = "flagged"
    return Quality(quality.astype(str), fix_bad, stretch, reach, speed, uncertain, unverified, alone, ~finite)


def off_the_track(positions: np.ndarray, covariances: np.ndarray, explained: np.ndarray, track: np.ndarray,
                  track_covariances: np.ndarray, track_explained: np.ndarray, track_ok: np.ndarray,
                  known_depth: np.ndarray | None = None, protection: np.ndarray | None = None) -> np.ndarray:
    """Which rows of another estimator of the same pings are off the track (module docstring): the track's row
    ``ok``, the two beyond the χ² gate :data:`FIX_GATE` of their covariances summed, and the track explaining at
    least as many of the ping's arrivals (:func:`explained`), or the row's own arrivals not checking it (none to
    spare beyond its dim + 1, a depth it was given counted as one more).

    Parameters
    ----------
    positions, track : ndarray, (m, ≥2)
        The estimator's rows and the track's at the same pings [m] (NaN where none); the horizontal position taken.
    covariances, track_covariances : ndarray, (m, ≥2, ≥2)
        Their own covariances [m²], without the terms common to both (the survey's, the sound speed's).
    explained, track_explained : ndarray of int, (m,)
        The arrivals of each ping that agree with the row and with the track's row.
    track_ok : ndarray of bool, (m,)
        Where the track's row is ``ok``.
    known_depth : ndarray of bool, (m,), optional
        The rows that were given the tag's depth (as :func:`check_track`'s). Default: none.
    protection : ndarray, (m,), optional
        The rows' horizontal protection levels [m] where they are single-ping fixes
        (:func:`~sblsim.models.tracking.integrity.protection_levels`): a row one faulty arrival could have put as far
        from the track as it is, unseen by its own test, is off however many arrivals it explains (a reflection it
        kept explains itself). Default: none assessed.

    Returns
    -------
    ndarray of bool, (m,)
    """
    p, q = np.asarray(positions, float)[:, :2], np.asarray(track, float)[:, :2]
    P, Q = np.asarray(covariances, float)[:, :2, :2], np.asarray(track_covariances, float)[:, :2, :2]
    both = np.isfinite(p).all(axis=1) & np.isfinite(q).all(axis=1) & np.isfinite(P + Q).all(axis=(1, 2))
    d2 = np.full(len(p), np.inf)
    d2[both] = _distance2(p[both] - q[both], P[both] + Q[both])
    unchecked = _to_spare(np.asarray(explained), known_depth, np.asarray(positions).shape[1]) < 1
    if protection is not None:  # one fault could have put the row there unseen: its arrivals do not check it
        with np.errstate(invalid="ignore"):
            unchecked |= np.asarray(protection, float) >= np.linalg.norm(p - q, axis=1)
    return (np.asarray(track_ok, bool) & both & ~(d2 <= FIX_GATE)
            & ((np.asarray(track_explained) >= np.asarray(explained)) | unchecked))


def with_track(quality: Quality, off: np.ndarray) -> Quality:
    """``quality`` with the rows ``off`` the track (:func:`off_the_track`, (m,) bool) flagged for it."""
    off = np.asarray(off, bool)
    marks = np.where(off, "flagged", quality.quality).astype(str)
    return replace(quality, quality=marks, track=off)


__all__ = ["EXPLAINED_SIGMAS", "FIX_GATE", "FIX_SLACK", "MAX_SPEED", "QUALITY", "REASONS", "TRUSTED_FIX_DRMS",
           "Quality", "check_track", "explained", "off_the_track", "reasons", "trusted_fixes", "with_track"]
