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

``dimension`` (default n) is the number of states that are uncertain, when P's other rows and columns are
zero (states known exactly: a receiver's error states it is not configured to use). The spread and the
weights are then those of a ``dimension``-state set, ``λ = α²(d + κ) − d``, ``L Lᵀ = (d + λ) P``,
``wm_i = wc_i = 1 / (2(d + λ))`` on all 2n points and ``wm_0 = 1 − n / (d + λ)``: the 2(n − d) points of
the exact states sit on the mean, so that together with the centre they carry the centre weight of the
d-state set, ``λ / (d + λ)``, and the transform equals the d-state one exactly (FilterPy's n-state set with
``κ + d − n`` in place of κ). With d = n it is the plain set. Without it a zero block of P would widen
the spread of the others, ``√(n + λ)`` standard deviations instead of ``√(d + λ)`` (α = 1, κ = 0: √14
in place of √6 for the ``ukf``'s 14 states, which took its error on the semicircle at T = 1 s from 0.6 m
to 6.8 m).

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

    def __init__(self, n: int, lam, dimension=None) -> None:
        self.n = n
        self.lam = lam
        self.dimension = n if dimension is None else dimension
        self._plain = dimension is None

    def centre_weight(self) -> ca.SX:
        """``wm_0``: ``λ / (d + λ)`` for d = n, else ``1 − n / (d + λ)`` (module docstring)."""
        d, lam = self.dimension, self.lam
        if self._plain:
            return lam / (d + lam)
        return 1.0 - self.n / (d + lam)

    @property
    def count(self) -> int:
        """Number of points, 2n + 1."""
        return 2 * self.n + 1

    def weights(self) -> tuple[ca.SX, ca.SX]:
        """Mean and covariance weights ``wm``, ``wc``, each (2n + 1, 1)."""
        raise NotImplementedError

    def points(self, x: ca.SX, P: ca.SX) -> list[ca.SX]:
        """The 2n + 1 points ``x, x + col_i(L), x − col_i(L)``, ``L = chol((d + λ) P)`` lower, each (n, 1).

        Raises
        ------
        ValueError
            If ``x`` does not have n rows.
        """
        if x.shape[0] != self.n:
            raise ValueError(f"sigma points of {self.n} states, got a state of {x.shape[0]}")
        L = cholesky((self.dimension + self.lam) * P)
        return [x] + [x + L[:, i] for i in range(self.n)] + [x - L[:, i] for i in range(self.n)]


class MerweScaledSigmaPoints(SigmaPoints):
    """Scaled sigma points of van der Merwe: spread α, prior weight β (2 for a Gaussian), secondary scaling κ."""

    def __init__(self, n: int, alpha, beta, kappa, dimension=None) -> None:
        d = n if dimension is None else dimension
        super().__init__(n, alpha**2 * (d + kappa) - d, dimension)
        self.alpha, self.beta, self.kappa = alpha, beta, kappa

    def weights(self) -> tuple[ca.SX, ca.SX]:
        n, lam = self.n, self.lam
        rest = 0.5 / (self.dimension + lam)
        centre = self.centre_weight()
        wm = ca.vertcat(centre, *([rest] * (2 * n)))
        wc = ca.vertcat(centre + (1.0 - self.alpha**2 + self.beta), *([rest] * (2 * n)))
        return wm, wc


class JulierSigmaPoints(SigmaPoints):
    """Julier and Uhlmann's sigma points: ``λ = κ`` (κ = 3 − n matches the fourth moment of a Gaussian)."""

    def __init__(self, n: int, kappa, dimension=None) -> None:
        super().__init__(n, kappa, dimension)
        self.kappa = kappa

    def weights(self) -> tuple[ca.SX, ca.SX]:
        rest = 0.5 / (self.dimension + self.kappa)
        wm = ca.vertcat(self.centre_weight(), *([rest] * (2 * self.n)))
        return wm, wm


__all__ = ["JulierSigmaPoints", "MerweScaledSigmaPoints", "SigmaPoints"]
