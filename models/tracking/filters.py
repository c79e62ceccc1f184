"""The other causal filters of a pinger's track: the sequential EKF and the unscented Kalman filter, on
:class:`~sblsim.models.tracking.ekf.ToaTracker`'s motion model, start and restarts.

References
----------
Bar-Shalom, Li, Kirubarajan, *Estimation with Applications to Tracking and Navigation*, Wiley 2001, § 3.6
(sequential processing); Wan & van der Merwe, "The unscented Kalman filter for nonlinear estimation", Proc. IEEE
AS-SPCC 2000; García-Fernández, Svensson, Morelande & Särkkä, "Posterior linearization filter: principles and
implementation using sigma points", IEEE Trans. Signal Processing 63(20), 2015.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.receiver.sigma_points import MerweScaledSigmaPoints
from sblsim.models.tracking.ekf import ToaTracker, TrackerSettings
from sblsim.models.tracking.toa import _evaluate_pings


class ToaSeqTracker(ToaTracker):
    """The sequential EKF of the same track (the ``ekf-seq`` receiver's update): :class:`ToaTracker`'s motion model,
    start and restarts, with one scalar update per time of arrival (sequential processing, Bar-Shalom, Li &
    Kirubarajan 2001, section 3.6), each gated alone by its NIS (``settings.gate``) against the state and
    covariance the arrivals before it left, the model linearised once at the prediction; the ping's arrivals are
    first screened as the EKF's are (by the ping's own single-ping fix where the set fails its test).

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    settings : TrackerSettings
    """

    def update(self, x: np.ndarray, P: np.ndarray, toa: np.ndarray, kept: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The arrivals of one ping (n,) (NaN: not heard) one at a time, in the receivers' order (``kept`` as
        :meth:`ToaTracker.update`'s); returns the state, the covariance (Joseph form) and the arrivals used (n,)."""
        d, s = self.dim, self.settings
        R = self._R  # [s²]: one, or each receiver's (n,)
        model, J = self._model(x[:d], x[-2])
        H = np.zeros((self.n, self.size))
        H[:, :d], H[:, -2] = J[:, :d], J[:, d]
        heard = np.isfinite(toa)
        W = self._consider_spread(model, x[-2])
        if heard.any() and not self._set_passes(heard, toa - model, H[heard] @ P @ H[heard].T + self._noise(heard)
                                                + W[np.ix_(heard, heard)]):
            heard = self._fix_kept(toa, heard, kept)
        prediction = x
        used = np.zeros(self.n, bool)
        for i in np.flatnonzero(heard):
            h = H[i]
            Ri = R[i] if self._per_receiver else R
            nu = toa[i] - (model[i] + h @ (x - prediction))
            S = h @ P @ h + Ri
            if nu**2 / (S + W[i, i]) > s.gate:
                continue
            k = P @ h / S
            x = x + k * nu
            A = self._eye - np.outer(k, h)
            P = A @ P @ A.T + Ri * np.outer(k, k)
            P = 0.5 * (P + P.T)
            used[i] = True
        return x, P, used


#: The scaled sigma points of :class:`ToaUkfTracker`: spread α, prior weight β (2: Gaussian), secondary scaling κ
#: (the ``ukf`` receiver's defaults; λ = α²(n + κ) − n = 0: the points at ±√n standard deviations, the centre
#: weighted in the covariance only).
UKF_ALPHA, UKF_BETA, UKF_KAPPA = 1.0, 2.0, 0.0


@lru_cache(maxsize=None)
def _sigma_function(size: int, alpha: float, beta: float, kappa: float) -> ca.Function:
    """``(x (size,), P (size, size)) -> (points (size, 2 size + 1), wm, wc (2 size + 1,))``: the scaled sigma points
    of :class:`~sblsim.models.receiver.sigma_points.MerweScaledSigmaPoints` (the ``ukf`` receiver's) as a
    function."""
    x, P = ca.SX.sym("x", size), ca.SX.sym("P", size, size)
    points = MerweScaledSigmaPoints(size, alpha, beta, kappa)
    wm, wc = points.weights()
    return ca.Function("sblsim_toa_sigma_points", [x, P], [ca.horzcat(*points.points(x, P)), wm, wc])


class ToaUkfTracker(ToaTracker):
    """The unscented Kalman filter of the same track: :class:`ToaTracker`'s motion model, start, gates and restarts,
    with the unscented measurement update (the motion model is linear, so its prediction is the EKF's), iterated about
    the posterior.

    The scaled sigma points (α, β, κ: :data:`UKF_ALPHA`, :data:`UKF_BETA`, :data:`UKF_KAPPA`; Wan & van der Merwe,
    "The unscented Kalman filter for nonlinear estimation", Proc. IEEE AS-SPCC 2000) go through
    :func:`toa_function`; their weighted mean, covariance and cross-covariance give the arrivals' statistical
    linearisation ``z ≈ H x + b`` with its error's covariance Ω (García-Fernández, Svensson, Morelande & Särkkä,
    "Posterior linearization filter: principles and implementation using sigma points", IEEE Trans. Signal
    Processing 63(20), 2015), which takes the place of the EKF's linearisation in the same gates (each arrival's
    NIS, then the set's) and in the Kalman update of the prediction. The first linearisation is about the
    prediction: with one iteration the update is the plain UKF's. Each further one is about the last update's
    mean and covariance (the iterated posterior linearisation filter), until the position moves by less than
    :data:`UKF_TOLERANCE` or :data:`UKF_ITERATIONS`: where the prediction is wide (a random burst interval's
    20–40 s after a start with the speed unknown: tens of metres across a ping heard by two receivers), sigma points
    spread over the prediction straddle the array and their statistics describe no arrival; about the posterior
    they shrink to where the arrivals put the tag.

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    settings : TrackerSettings
    alpha, beta, kappa : float
        The sigma points' parameters.
    iterations : int
        The linearisations of an update, at most (1: the plain UKF).
    """

    def __init__(self, receivers: np.ndarray, settings: TrackerSettings, alpha: float = UKF_ALPHA,
                 beta: float = UKF_BETA, kappa: float = UKF_KAPPA, iterations: int | None = None) -> None:
        super().__init__(receivers, settings)
        self._sigma = _sigma_function(self.size, float(alpha), float(beta), float(kappa))
        self.iterations = UKF_ITERATIONS if iterations is None else int(iterations)

    def _linearised(self, x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The arrivals' statistical linearisation about ``N(x, P)``: H (n, s), b (n,) [s] and Ω (n, n) [s²]."""
        d, s = self.dim, self.settings
        points, wm, wc = (np.asarray(v) for v in self._sigma(x, P))
        wm, wc = wm.ravel(), wc.ravel()
        Z = _evaluate_pings(self.receivers, s.sound_speed, points[:d].T, points[-2])[0]  # (2 size + 1, n)
        mean = wm @ Z
        dZ, dX = Z - mean, points.T - x
        Pzz = (wc[:, None] * dZ).T @ dZ
        Pxz = (wc[:, None] * dX).T @ dZ
        H = np.linalg.lstsq(P, Pxz, rcond=None)[0].T  # Pxzᵀ P⁻¹ (P symmetric)
        return H, mean - H @ x, Pzz - H @ P @ H.T

    def update(self, x: np.ndarray, P: np.ndarray, toa: np.ndarray, kept: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The iterated unscented update with one ping's times of arrival (n,) (NaN: not heard), gated as the EKF's
        (``kept`` as :meth:`ToaTracker.update`'s); returns the state, the covariance and the arrivals used (n,)."""
        R = self._R  # [s²]: one, or each receiver's (n,)
        at, spread = x, P
        used = np.zeros(self.n, bool)
        for _ in range(max(self.iterations, 1)):
            H, b, omega = self._linearised(at, spread)
            Pzz = H @ P @ H.T + omega
            nu = toa - (H @ x + b)
            W = self._consider_spread(H @ at + b, at[-2])

            def S(used, Pzz=Pzz, W=W):
                return Pzz[np.ix_(used, used)] + self._noise(used) + W[np.ix_(used, used)]

            used, Su = self._gated(toa, nu, np.diag(Pzz) + R + np.diag(W), S, kept)
            if Su is None:
                return x, P, used
            Su = Su - W[np.ix_(used, used)]
            K = np.linalg.solve(Su, H[used] @ P).T
            moved = x + K @ nu[used]
            covariance = P - K @ Su @ K.T
            covariance = 0.5 * (covariance + covariance.T)
            done = np.abs(moved[:self.dim] - at[:self.dim]).max() < UKF_TOLERANCE
            at, spread = moved, covariance
            if done:
                break
        return at, spread, used


#: The linearisations of :class:`ToaUkfTracker`'s update, at most, and the position change [m] below which it stops.
UKF_ITERATIONS, UKF_TOLERANCE = 10, 1e-4


#: The causal filters of a pinger's track by their receivers' names (one model, start and restarts; their own
#: measurement update).
CAUSAL_TRACKERS = {"ekf": ToaTracker, "ekf-seq": ToaSeqTracker, "ukf": ToaUkfTracker}


__all__ = ["CAUSAL_TRACKERS", "UKF_ALPHA", "UKF_BETA", "UKF_ITERATIONS", "UKF_KAPPA", "UKF_TOLERANCE", "ToaSeqTracker",
           "ToaUkfTracker"]
