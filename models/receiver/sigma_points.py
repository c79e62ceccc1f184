"""Sigma points of the unscented transform, as small objects (like FilterPy's).

A sigma-point set of an n-dimensional Gaussian ``N(x, P)`` is 2n + 1 points
``x, x ± col_i(L)`` with ``L Lᵀ = (n + λ) P`` (the lower Cholesky factor),
and mean and covariance weights ``wm``, ``wc`` (each (2n + 1, 1)). Two sets:

* :class:`MerweScaledSigmaPoints` (α, β, κ): ``λ = α²(n + κ) − n``,
  ``wm_0 = λ / (n + λ)``, ``wc_0 = wm_0 + 1 − α² + β``,
  ``wm_i = wc_i = 1 / (2(n + λ))``; the ``ukf`` receiver's.
* :class:`JulierSigmaPoints` (κ): ``λ = κ``, ``wm_0 = wc_0 = κ / (n + κ)``,
  ``wm_i = wc_i = 1 / (2(n + κ))``.

The parameters may be numbers or casadi expressions (the receivers' parameters).

References
----------
Julier, Uhlmann, "A new extension of the Kalman filter to nonlinear
systems", Proc. SPIE 3068, 1997 (the κ set). Wan, van der Merwe, "The
unscented Kalman filter for nonlinear estimation", Proc. IEEE AS-SPCC, 2000,
and van der Merwe, Sigma-point Kalman filters for probabilistic inference in
dynamic state-space models, PhD thesis, OGI 2004 (the scaled set).
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.receiver.kalman import cholesky


class SigmaPoints:
    """Base of the sigma-point sets: ``n`` states and the spread ``lam`` (λ); subclasses give the weights."""

    def __init__(self, n: int, lam) -> None:
        self.n = n
        self.lam = lam

    @property
    def count(self) -> int:
        """Number of points, 2n + 1."""
        return 2 * self.n + 1

    def weights(self) -> tuple[ca.SX, ca.SX]:
        """Mean and covariance weights ``wm``, ``wc``, each (2n + 1, 1)."""
        raise NotImplementedError

    def points(self, x: ca.SX, P: ca.SX) -> list[ca.SX]:
        """The 2n + 1 points ``x, x + col_i(L), x − col_i(L)``, ``L = chol((n + λ) P)`` lower, each (n, 1).

        Raises
        ------
        ValueError
            If ``x`` does not have n rows.
        """
        if x.shape[0] != self.n:
            raise ValueError(f"sigma points of {self.n} states, got a state of {x.shape[0]}")
        L = cholesky((self.n + self.lam) * P)
        return [x] + [x + L[:, i] for i in range(self.n)] + [x - L[:, i] for i in range(self.n)]


class MerweScaledSigmaPoints(SigmaPoints):
    """Scaled sigma points of van der Merwe: spread α, prior weight β (2 for a Gaussian), secondary scaling κ."""

    def __init__(self, n: int, alpha, beta, kappa) -> None:
        super().__init__(n, alpha**2 * (n + kappa) - n)
        self.alpha, self.beta, self.kappa = alpha, beta, kappa

    def weights(self) -> tuple[ca.SX, ca.SX]:
        n, lam = self.n, self.lam
        rest = 0.5 / (n + lam)
        wm = ca.vertcat(lam / (n + lam), *([rest] * (2 * n)))
        wc = ca.vertcat(lam / (n + lam) + (1.0 - self.alpha**2 + self.beta), *([rest] * (2 * n)))
        return wm, wc


class JulierSigmaPoints(SigmaPoints):
    """Julier and Uhlmann's sigma points: ``λ = κ`` (κ = 3 − n matches the fourth moment of a Gaussian)."""

    def __init__(self, n: int, kappa) -> None:
        super().__init__(n, kappa)
        self.kappa = kappa

    def weights(self) -> tuple[ca.SX, ca.SX]:
        n, kappa = self.n, self.kappa
        rest = 0.5 / (n + kappa)
        wm = ca.vertcat(kappa / (n + kappa), *([rest] * (2 * n)))
        return wm, wm


__all__ = ["JulierSigmaPoints", "MerweScaledSigmaPoints", "SigmaPoints"]
