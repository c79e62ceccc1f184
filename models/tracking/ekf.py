"""The extended Kalman filter of a pinger's track from its times of arrival, and the Rauch-Tung-Striebel smoother.

State ``[p, v, t_e, Δ]`` (position [m], velocity [m/s], emission time [s], ping interval [s]) with a
nearly-constant-velocity motion model (white-noise acceleration) over each step of the ping schedule
(:mod:`sblsim.models.tracking.schedule`), the emission time advancing by the step and the interval a random walk;
the times of arrival of each ping gated by their NIS (each one, then the ping's set), restarted from a single-ping
fix when lost.

References
----------
Bar-Shalom, Li, Kirubarajan, *Estimation with Applications to Tracking and Navigation*, Wiley 2001, Sections 5.4
(NIS), 6.2 (white-noise acceleration model), 10.3 (the EKF) and 11.7 (M-of-N track initiation). Rauch, Tung,
Striebel, "Maximum likelihood estimates of linear dynamic systems", AIAA Journal 3(8), 1965 (the smoother).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import get_lapack_funcs

from sblsim.models.tracking.fix import GATE_ONE, Fix, single_ping_fix
from sblsim.models.tracking.schedule import PingSchedule
from sblsim.models.tracking.toa import PingModel, checked_sigma, per_receiver


@dataclass
class TrackerSettings:
    """The tracker's model.

    Attributes
    ----------
    sound_speed : float
        [m/s].
    sigma_toa : float or ndarray, (n,)
        Standard deviation of a time of arrival [s]: one for every receiver, or each receiver's own in the
        receivers' order (a synchronisation's residuals per receiver), the measurement covariance then
        ``diag(σ_i²)`` in every estimator (the fix, the filters, the smoothers). What takes a single value (a late
        arrival's ``delay_mean`` in units of σ_toa) takes the receivers' median.
    acceleration_psd : float
        Power spectral density of the white-noise acceleration, per axis [m²/s³].
    interval : float
        The nominal ping interval, the initial Δ [s].
    sigma_interval : float
        Initial standard deviation of Δ [s].
    jitter : float
        Standard deviation of the emission time's step beyond Δ, per ping [s].
    interval_drift : float
        Standard deviation of Δ's random-walk step, per ping [s].
    sigma_speed : float
        Initial standard deviation of each velocity component [m/s].
    gate : float
        χ²(1) threshold of one time of arrival's NIS.
    gate_probability : float
        Probability that the χ² test of a ping's set of times of arrival passes a consistent set.
    reinit_after : int
        Pings heard by dim + 2 or more receivers, every arrival refused, after which the filter starts again from a
        single-ping fix.
    fix_gate : float
        The squared Mahalanobis distance (against the prediction's and the fix's position covariances summed)
        beyond which an overdetermined single-ping fix (dim + 3 receivers or more) disagrees with the prediction
        (χ²(2) at 1 − 2·10⁻⁹ is 40).
    disagree_after : int
        Consecutive disagreeing pings after which the filter starts again from a single-ping fix (it is lost:
        a diverged filter with a grown covariance keeps accepting arrivals, so the refusals alone rarely restart
        it); only when :meth:`ToaTracker.run` is given the fixes.
    agree_after : int or None
        Consecutive single-ping fixes of dim + 2 receivers or more that kept every arrival of their ping, each
        outside the prediction's ``fix_gate`` and each agreeing with the previous one (below), after which the
        filter starts again from a fix; None: off. An array of few receivers rarely gives the dim + 3 of
        ``disagree_after``, and a fix of dim + 2 receivers has one redundant arrival only (a gross fix passes its
        own test more often), so a single one must not restart: the sequence is the confirmation, the M-of-N
        logic of track initiation (Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
        Navigation*, Wiley 2001, § 11.7; Blackman & Popoli, *Design and Analysis of Modern Tracking Systems*,
        1999, § 6.3). A fix that dropped an arrival (multipath) neither counts nor breaks the sequence.
    fix_speed : float
        [m/s]. Two consecutive fixes of the ``agree_after`` sequence agree when their squared Mahalanobis distance,
        against their position covariances summed plus ``(fix_speed · elapsed time)² / fix_gate`` per axis (so
        that a move of ``fix_speed`` over the elapsed time sits on the gate), is at most ``fix_gate``.
    depth_sigma : float
        Standard deviation of a tag's depth-sensor reading [m] (the fix and the robust smoother take a reading as a
        measurement of the height ``z = −depth``): 0.3 m, a pressure sensor of 0.5 % of a 50 m range, the class of
        the telemetry tags' depth sensors.
    survey_sigma : ndarray, (n,), or None
        Standard deviation of each receiver's surveyed position per axis [m] (None: exact). The fix's and the
        robust smoother's covariances hold its effect as a consider covariance (the positions not estimated, their
        error propagated: Tapley, Schutz & Born, *Statistical Orbit Determination*, Elsevier 2004, § 6.3); the
        causal filters and the RTS smoother take none (their consider terms are
        :mod:`~sblsim.models.tracking.filter_consider`'s, from their records).
    sound_speed_sigma : float or None
        The sound speed's standard error [m/s] (None: exact). With ``survey_sigma``, the causal filters' gates take
        the arrivals' error from both (each receiver's ``(σ_i / c)²``, the speed's ``σ_c² g gᵀ`` with
        ``g_i = ρ_i / c²``, common to the ping's arrivals) beside their innovations' covariance, so that an arrival
        the bias moved is not refused for it; their gains stay their own (the consider terms of their covariances
        are :mod:`~sblsim.models.tracking.filter_consider`'s).
    delay_share : float
        Probability that a time of arrival is late (multipath, a blocked direct path), in [0, 1): the robust
        smoother's one-sided delay term (:mod:`~sblsim.models.tracking.arrival_model`); 0: the Student-t alone.
    delay_mean : float
        A late arrival's mean delay beyond the direct path [s] (> 0 where ``delay_share`` > 0).
    delay_dof : float
        ν of the direct arrivals' Student-t core where late arrivals are modelled (``delay_share`` > 0; else the
        smoother's own ν, :data:`~sblsim.models.tracking.smoother_cost.ROBUST_DOF`): the late ones no longer in its
        tail, an early residual is costly (a track that makes arrivals early to explain late ones is not a minimum).
    """

    sound_speed: float
    sigma_toa: float | np.ndarray = 2e-4
    acceleration_psd: float = 0.01
    interval: float = 2.0
    sigma_interval: float = 0.05
    jitter: float = 1e-3
    interval_drift: float = 1e-4
    sigma_speed: float = 1.0
    gate: float = GATE_ONE
    gate_probability: float = 0.999
    reinit_after: int = 3
    fix_gate: float = 40.0
    disagree_after: int = 5
    agree_after: int | None = None
    fix_speed: float = 2.0
    depth_sigma: float = 0.3
    survey_sigma: np.ndarray | None = None
    sound_speed_sigma: float | None = None
    delay_share: float = 0.0
    delay_mean: float = 1e-3
    delay_dof: float = 10.0


@dataclass
class TrackRecord:
    """What :meth:`ToaTracker.run` records: per ping k (m pings), state size s = 2 dim + 2.

    Attributes
    ----------
    x_filtered, P_filtered : ndarray, (m, s), (m, s, s)
        The EKF's estimate after ping k (NaN before the filter starts).
    x_predicted, P_predicted : ndarray, (m, s), (m, s, s)
        The prediction of ping k from ping k − 1.
    F : ndarray, (m, s, s)
        The transition's Jacobian from ping k − 1 to k.
    used : ndarray of bool, (m, n)
        The times of arrival the update used.
    start : int
        The first ping with an estimate.
    restarts : list of int
        The pings where the filter started again from a single-ping fix.
    """

    x_filtered: np.ndarray
    P_filtered: np.ndarray
    x_predicted: np.ndarray
    P_predicted: np.ndarray
    F: np.ndarray
    used: np.ndarray
    start: int
    restarts: list[int] = field(default_factory=list)


class ToaTracker:
    """EKF and RTS smoother of a pinger's track from times of arrival, the emission times unknown.

    State ``x = [p (dim), v (dim), t_e, Δ]``; from ping k − 1 to ping k (one row of the TOA matrix each, heard or
    not), with ``T = Δ``:

        ``p ← p + T v``, ``v ← v``, ``t_e ← t_e + Δ``, ``Δ ← Δ``,

    process noise ``q [T³/3, T²/2; T²/2, T]`` per axis (white-noise acceleration), ``jitter²`` on ``t_e`` and
    ``interval_drift²`` on ``Δ``. The update of ping k uses :func:`toa_function` with the receivers that heard
    it, gated one by one (NIS against ``settings.gate``) and then as a set (the χ² quantile of
    ``settings.gate_probability``): a set that fails with dim + 3 arrivals or more is first cut to those the
    ping's own single-ping fix keeps, then the largest NIS is dropped until it passes.

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    settings : TrackerSettings
    """

    def __init__(self, receivers: np.ndarray, settings: TrackerSettings) -> None:
        self.receivers = np.asarray(receivers, float)
        self.n, self.dim = self.receivers.shape
        self.settings = settings
        self.size = 2 * self.dim + 2
        self._model = PingModel(self.receivers, settings.sound_speed)  # the TOA model and its Jacobian
        self._eye, self._eye_dim = np.eye(self.size), np.eye(self.dim)
        self._eyes = [np.eye(k) for k in range(self.n + 1)]  # the identities of 0 to n arrivals
        # without consider terms their covariance (:meth:`_consider_spread`) is zero: its diagonal and its blocks of 0
        # to n arrivals made once, added as the zeros they are (the same sums, the same numbers)
        self._considered = settings.survey_sigma is not None or bool(settings.sound_speed_sigma)
        self._no_spread, self._zeros = np.zeros(self.n), [np.zeros((k, k)) for k in range(self.n + 1)]
        self._R = checked_sigma(settings.sigma_toa, self.n) ** 2  # [s²]: one, or each receiver's (n,)
        self._per_receiver = per_receiver(self._R)
        from scipy.stats import chi2

        self._set_gate = chi2.ppf(settings.gate_probability, np.arange(1, self.n + 1))
        self._gesv = get_lapack_funcs("gesv", (self._eye,))

    def transition(self, x: np.ndarray, step: int | None = None, schedule: PingSchedule | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The prediction of the next ping: state (s,), the Jacobian F (s, s), the process noise Q (s, s), over the
        step ``step`` of ``schedule`` (:class:`~sblsim.models.tracking.schedule.PingSchedule`; default one stable
        interval), its duration at the state's interval: the same numbers as
        :func:`~sblsim.models.receiver.toa_bound.predict` and :func:`~sblsim.models.receiver.toa_bound.process_noise`
        of the one state."""
        s = self.settings
        if schedule is None or step is None:
            count, offset, te, drift = 1.0, 0.0, s.jitter, s.interval_drift
        else:
            count, offset = schedule.count[step], schedule.offset[step]
            te, drift = schedule.te_sigma[step], schedule.drift_sigma[step]
        # toa_bound's predict and process_noise of one row, their operations on one state's numbers (the same
        # numbers to the last bit: each product and sum as those functions make it; T's powers on a one-element
        # array, as theirs are): called every ping, their arrays of one row cost the EKF a third of its loop
        d, q = self.dim, s.acceleration_psd
        T = count * float(x[-1]) + offset
        xp = x.copy()
        xp[:d] += T * x[d:2 * d]
        xp[-2] += T
        F = self._eye.copy()
        F[:d, d:2 * d] = T * self._eye_dim
        F[:d, -1] = count * x[d:2 * d]
        F[-2, -1] = count
        steps = np.array([T])
        Q = np.zeros((self.size, self.size))
        Q[:d, :d] = (q * steps**3 / 3)[0] * self._eye_dim
        Q[:d, d:2 * d] = Q[d:2 * d, :d] = (q * steps**2 / 2)[0] * self._eye_dim
        Q[d:2 * d, d:2 * d] = (q * steps)[0] * self._eye_dim
        Q[-2, -2] = float(te) * float(te)
        Q[-1, -1] = float(drift) * float(drift)
        return xp, F, Q

    def initial(self, fix: Fix) -> tuple[np.ndarray, np.ndarray]:
        """The state and covariance started from a single-ping fix (velocity 0, the nominal interval)."""
        d, s = self.dim, self.settings
        x = np.concatenate([fix.position, np.zeros(d), [fix.emission, s.interval]])
        P = np.zeros((self.size, self.size))
        idx = list(range(d)) + [2 * d]
        P[np.ix_(idx, idx)] = fix.covariance
        P[d:2 * d, d:2 * d] = s.sigma_speed**2 * np.eye(d)
        P[-1, -1] = s.sigma_interval**2
        return x, P

    def update(self, x: np.ndarray, P: np.ndarray, toa: np.ndarray, kept: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The EKF update with one ping's times of arrival (n,) (NaN: not heard), gated (:meth:`_gated`, ``kept``
        (n,) the arrivals the ping's single-ping fix keeps, if known); returns the state, the covariance (Joseph
        form) and the arrivals used (n,)."""
        d = self.dim
        model, J = self._model(x[:d], x[-2])
        H = np.zeros((self.n, self.size))
        H[:, :d] = J[:, :d]
        H[:, -2] = J[:, d]
        R = self._R
        nu = toa - model

        if self._considered:
            W = self._consider_spread(model, x[-2])
            spread, block = np.diag(W), (lambda used: W[used][:, used])
        else:
            spread, block = self._no_spread, (lambda used: self._zeros[int(used.sum())])

        def S(used):
            Hu = H[used]
            return Hu @ P @ Hu.T + self._noise(used) + block(used)

        used, Su = self._gated(toa, nu, np.einsum("ij,jk,ik->i", H, P, H) + R + spread, S, kept)
        if Su is not None:
            Hu = H[used]
            K = np.linalg.solve(Su - block(used), Hu @ P).T
            x = x + K @ nu[used]
            A = self._eye - K @ Hu
            P = A @ P @ A.T + self._gain_noise(K, used)
            P = 0.5 * (P + P.T)
        return x, P, used

    def _solve(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``a⁻¹ b`` for a gate's χ² (a small square ``a`` (k, k), ``b`` (k,)): LAPACK's ``gesv`` (LU with partial
        pivoting, as :func:`numpy.linalg.solve`) called directly, without numpy's wrapper, whose checks cost a
        filter's step several times the solve itself. For the gates' decisions alone: scipy's LAPACK is not
        numpy's build, and the two may differ in a last bit, which moves a decision only on a χ² within a rounding
        of its gate; the gain, which the state takes, keeps :func:`numpy.linalg.solve`.

        Raises
        ------
        numpy.linalg.LinAlgError
            Where ``a`` is singular (as :func:`numpy.linalg.solve`).
        """
        x, info = self._gesv(a, b)[2:]
        if info != 0:
            raise np.linalg.LinAlgError("Singular matrix")
        return x

    def _noise(self, used: np.ndarray) -> np.ndarray:
        """The measurement covariance R [s²] of the arrivals ``used`` (n,) bool: ``σ² I``, or ``diag(σ_i²)`` with a
        timing noise per receiver."""
        if self._per_receiver:
            return np.diag(self._R[used])
        return self._R * self._eyes[int(used.sum())]

    def _gain_noise(self, K: np.ndarray, used: np.ndarray) -> np.ndarray:
        """``K R Kᵀ`` of the Joseph form for the gain K (s, k) of the arrivals ``used`` (n,) bool."""
        if self._per_receiver:
            return (K * self._R[used]) @ K.T
        return self._R * K @ K.T

    def _consider_spread(self, model: np.ndarray, emission: float) -> np.ndarray:
        """The covariance (n, n) [s²] of the arrivals' error from the receivers' survey and the sound speed's error
        (``settings.survey_sigma``, ``settings.sound_speed_sigma``; zero without), for the gates: ``diag((σ_i /
        c)²) + σ_c² g gᵀ``, ``g_i = (m_i − t_e) / c`` the travel times' derivative by the speed (``model`` (n,) [s]
        the arrivals' model, ``emission`` [s])."""
        s = self.settings
        W = np.zeros((self.n, self.n))
        if s.survey_sigma is not None:
            W[np.diag_indices(self.n)] = (np.asarray(s.survey_sigma, float) / s.sound_speed) ** 2
        if s.sound_speed_sigma:
            g = (np.asarray(model, float) - emission) / s.sound_speed * s.sound_speed_sigma
            W += np.outer(g, g)
        return W

    def _gated(self, toa: np.ndarray, nu: np.ndarray, variance: np.ndarray, S, kept: np.ndarray | None
               ) -> tuple[np.ndarray, np.ndarray | None]:
        """The arrivals (n,) a ping's update uses, and their innovations' covariance (None when none is used):
        each heard one whose NIS (innovation ``nu`` (n,) [s] over its ``variance`` (n,) [s²]) passes
        ``settings.gate``; then as a set (``S(used)`` the predicted covariance [s²] of the innovations of the
        arrivals ``used`` (n,) bool) against the χ² quantile of ``settings.gate_probability``: a set that fails is
        first cut to the arrivals the ping's single-ping fix keeps (:meth:`_fix_kept`), then its largest NIS is
        dropped until it passes."""
        used = np.isfinite(toa)
        used[used] = nu[used] ** 2 / variance[used] <= self.settings.gate
        screened = False
        while used.any():
            Su = S(used)
            if self._set_passes(used, nu, Su):
                return used, Su
            if not screened:
                screened, cut = True, self._fix_kept(toa, used, kept)
                if not np.array_equal(cut, used):
                    used = cut
                    continue
            used[np.flatnonzero(used)[int(np.argmax(nu[used] ** 2 / variance[used]))]] = False
        return used, None

    def _set_passes(self, used: np.ndarray, nu: np.ndarray, Su: np.ndarray) -> bool:
        """Whether the arrivals ``used`` (n,) pass the set's χ² test, ``Su`` their innovations' covariance [s²]."""
        return float(nu[used] @ self._solve(Su, nu[used])) <= self._set_gate[int(used.sum()) - 1]

    def _fix_kept(self, toa: np.ndarray, used: np.ndarray, kept: np.ndarray | None) -> np.ndarray:
        """The arrivals ``used`` (n,) of a ping cut, with redundancy to spare (dim + 3 or more), to those its own
        single-ping fix keeps (``kept`` (n,), computed here when None). After a poor prediction (the velocity
        unknown at the start, a turn) the prediction's residuals cannot tell a late multipath arrival from the good
        ones, and dropping the largest of them until the set passes can drop the good ones and keep the late; the
        fix's own residuals single it out."""
        if int(used.sum()) < self.dim + 3:
            return used
        if kept is None:
            fix = single_ping_fix(toa, self.receivers, self.settings.sound_speed, self.settings.sigma_toa)
            kept = None if fix is None else fix.used
        return used if kept is None else used & kept

    def run(self, toa: np.ndarray, fixes: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
            kept: np.ndarray | None = None, schedule: PingSchedule | None = None) -> TrackRecord:
        """The EKF over every ping (rows of ``toa``, (m, n) [s], NaN: not heard), started at the first ping with a
        single-ping fix of dim + 2 receivers or more, and started again from a fix after ``reinit_after``
        pings whose arrivals were all refused or, given ``fixes`` (the single-ping fixes of every ping: positions
        (m, dim) [m], NaN where none, covariances (m, ≥dim, ≥dim) [m²] and the receivers each used (m,), as
        :func:`fix_pings` returns them), after ``disagree_after`` consecutive overdetermined fixes outside the
        prediction's ``fix_gate``, or after ``agree_after`` consecutive mutually consistent fixes of dim + 2
        receivers or more outside it (:class:`TrackerSettings`). ``kept`` (m, n): the arrivals each ping's
        single-ping fix keeps (:func:`fix_pings`' ``used``), for the screening of a set that fails its test
        (computed ping by ping where needed when not given). ``schedule``: the steps between the rows
        (:class:`~sblsim.models.tracking.schedule.PingSchedule`, default one stable interval each); the first ping
        after each of its gaps starts a new segment (the filter started again from a fix there)."""
        m, size, s = len(toa), self.size, self.settings
        if schedule is None:
            schedule = PingSchedule.stable(m, s.interval, s.jitter, s.interval_drift)
        times, gaps = schedule.times(), set(schedule.gaps)
        rec = TrackRecord(np.full((m, size), np.nan), np.full((m, size, size), np.nan), np.full((m, size), np.nan),
                          np.full((m, size, size), np.nan), np.tile(np.eye(size), (m, 1, 1)),
                          np.zeros((m, self.n), bool), m)
        x = P = None
        refused = disagree = 0
        chain, agreeing = None, 0
        d = self.dim
        heard = np.isfinite(toa).sum(axis=1)
        for k in range(m):
            if x is not None:
                xp, F, Q = self.transition(x, k - 1, schedule)
                P = F @ P @ F.T + Q
                x = xp
                rec.x_predicted[k], rec.P_predicted[k], rec.F[k] = x, P, F
                segment = k - 1 in gaps  # a new segment: started again from a fix
                if not segment and fixes is not None and np.isfinite(fixes[0][k]).all() and fixes[2][k] >= d + 2:
                    # an overdetermined single-ping fix far outside the prediction's ellipse: the filter may be lost
                    e = fixes[0][k] - x[:d]
                    far = float(e @ self._solve(P[:d, :d] + fixes[1][k][:d, :d], e)) > s.fix_gate
                    if fixes[2][k] >= d + 3:
                        disagree = disagree + 1 if far else 0
                    if not far:
                        chain, agreeing = None, 0
                    elif s.agree_after is not None and fixes[2][k] == heard[k]:
                        # a fix that kept every arrival of its ping counts if it agrees with the previous such fix
                        # (the same target, moved at most fix_speed since): one gross fix does not restart, a
                        # consistent sequence does
                        if chain is not None:
                            gap = fixes[0][k] - fixes[0][chain]
                            allowed = fixes[1][k][:d, :d] + fixes[1][chain][:d, :d] + \
                                (s.fix_speed * (times[k] - times[chain])) ** 2 / s.fix_gate * np.eye(d)
                            agreeing = agreeing + 1 if float(gap @ self._solve(allowed, gap)) <= s.fix_gate else 1
                        else:
                            agreeing = 1
                        chain = k
                if segment:
                    refused = s.reinit_after
                else:
                    x, P, used = self.update(x, P, toa[k], None if kept is None else kept[k])
                    rec.used[k] = used
                    refused = refused + 1 if heard[k] >= self.dim + 2 and not used.any() else 0
                if disagree >= s.disagree_after or (s.agree_after is not None and agreeing >= s.agree_after):
                    refused = s.reinit_after
            if x is None or refused >= s.reinit_after:
                disagree, chain, agreeing = 0, None, 0
                fix = single_ping_fix(toa[k], self.receivers, s.sound_speed, s.sigma_toa) \
                    if heard[k] >= self.dim + 2 else None
                if fix is None:
                    if x is not None:  # no fix to start again from: the prediction kept (coasting, not positioned)
                        rec.x_filtered[k], rec.P_filtered[k] = x, P
                    continue
                if x is None:
                    rec.start = k
                    rec.x_predicted[k], rec.P_predicted[k] = self.initial(fix)
                else:
                    rec.restarts.append(k)
                x, P = self.initial(fix)
                if k > rec.start:  # the prediction of this ping stays the filter's; keep the interval
                    x[-1] = rec.x_predicted[k][-1]
                    P[-1, -1] = rec.P_predicted[k][-1, -1]
                rec.used[k] = fix.used
                refused = 0
            rec.x_filtered[k], rec.P_filtered[k] = x, P
        return rec

    def smooth(self, rec: TrackRecord) -> tuple[np.ndarray, np.ndarray]:
        """The RTS smoother over the filter's record from its first ping (:func:`rts_smooth`); NaN before it.
        Returns the smoothed states (m, s) and covariances (m, s, s)."""
        xs = np.full_like(rec.x_filtered, np.nan)
        Ps = np.full_like(rec.P_filtered, np.nan)
        k0 = rec.start
        if k0 < len(xs):
            xs[k0:], Ps[k0:] = rts_smooth(rec.x_filtered[k0:], rec.P_filtered[k0:], rec.x_predicted[k0:],
                                          rec.P_predicted[k0:], rec.F[k0:])
        return xs, Ps


def rts_smooth(x_filtered: np.ndarray, P_filtered: np.ndarray, x_predicted: np.ndarray, P_predicted: np.ndarray,
               F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fixed-interval Rauch-Tung-Striebel smoother over a Kalman filter's (or EKF's) record.

    For k = m − 2 down to 0, with ``C_k = P_k|k F_{k+1}ᵀ P_{k+1|k}⁻¹``:
    ``x_k|m = x_k|k + C_k (x_{k+1}|m − x_{k+1|k})`` and ``P_k|m = P_k|k + C_k (P_{k+1}|m − P_{k+1|k}) C_kᵀ``.

    Parameters
    ----------
    x_filtered, P_filtered : ndarray, (m, s), (m, s, s)
        Filtered states and covariances.
    x_predicted, P_predicted : ndarray, (m, s), (m, s, s)
        Row k: the prediction of step k from step k − 1 (row 0 is not used).
    F : ndarray, (m, s, s)
        Row k: the transition (its Jacobian) from step k − 1 to k (row 0 is not used).

    Returns
    -------
    x_smoothed : ndarray, (m, s)
    P_smoothed : ndarray, (m, s, s)
    """
    xs = np.array(x_filtered, float)
    Ps = np.array(P_filtered, float)
    gains = rts_gains(P_filtered, P_predicted, F)
    for k in range(len(xs) - 2, -1, -1):
        C = gains[k]
        xs[k] = x_filtered[k] + C @ (xs[k + 1] - x_predicted[k + 1])
        Ps[k] = P_filtered[k] + C @ (Ps[k + 1] - P_predicted[k + 1]) @ C.T
        Ps[k] = 0.5 * (Ps[k] + Ps[k].T)
    return xs, Ps


def rts_gains(P_filtered: np.ndarray, P_predicted: np.ndarray, F: np.ndarray) -> np.ndarray:
    """The RTS smoother's gains ``C_k = P_k|k F_{k+1}ᵀ P_{k+1|k}⁻¹`` (m − 1, s, s) of a filter's record (m rows, as
    :func:`rts_smooth` takes them): they depend on the filter alone, so they are solved for every row at once (the
    same LAPACK solve per row, the same numbers as one at a time)."""
    if len(P_filtered) < 2:
        return np.empty((0, *np.shape(P_filtered)[1:]))
    return np.swapaxes(np.linalg.solve(P_predicted[1:], F[1:] @ P_filtered[:-1]), 1, 2)


__all__ = ["ToaTracker", "TrackRecord", "TrackerSettings", "rts_gains", "rts_smooth"]
