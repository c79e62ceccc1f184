"""A time of arrival's error in the robust smoother: a Student-t core and, optionally, a one-sided multipath delay.

A direct arrival's error is Student-t (ν degrees of freedom, scale σ_toa: Lange, Little & Taylor 1989). A late one
(a reflection, the direct path blocked) arrives after it by a delay δ ≥ 0: with probability π (``delay_share``) the
arrival is the direct one's time plus an exponential delay of mean μ (``delay_mean``) plus Gaussian noise of σ_toa,
an exponentially modified Gaussian (the channel's multipath excess, :mod:`sblsim.models.acoustics`; the ex-Gaussian
of Grushka, Anal. Chem. 44(11), 1972). In units of σ_toa, with the normalised residual z and λ = μ / σ_toa:

    ``p(z) = (1 − π) t_ν(z) + π f(z)``,  ``f(z) = (1/λ) exp(1/(2λ²) − z/λ) Φ(z − 1/λ)``.

Given that an arrival is late, its delay is N(z − 1/λ, 1) truncated to δ ≥ 0, so its mean δ̂ and variance follow
from the inverse Mills ratio (Johnson, Kotz & Balakrishnan, *Continuous Univariate Distributions* 1, Wiley 1994,
§ 13.10.1). The smoother's Gauss-Newton step takes each arrival's half gradient of ``−2 ln p``, by Fisher's identity
the expectation of the complete data's over the late arrival's posterior (probability γ, delay δ̂):

    ``g = (1 − γ) w_t z + γ (z − δ̂)``,  ``w_t = (ν + 1) / (ν + z²)``,

and the EM weight ``h = (1 − γ) w_t + γ`` (positive: a descent direction; Dempster, Laird & Rubin, JRSS B 39(1),
1977). With π = 0 these are the Student-t's own: ``g = w_t z``, ``h = w_t``, the cost term ``(ν + 1) ln(1 + z²/ν)``.
A late arrival's delay is then explained rather than weighed down only: a track that puts it early costs more than
one that puts it late by the same amount.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import gammaln, log_ndtr

_LOG_SQRT_2PI = 0.5 * np.log(2.0 * np.pi)


@dataclass(frozen=True)
class ArrivalModel:
    """The error of a time of arrival in σ_toa units.

    Attributes
    ----------
    dof : float
        ν of the Student-t core [1].
    share : float
        π, the probability that an arrival is late, in [0, 1).
    mean : float
        λ, a late arrival's mean delay [σ_toa] (> 0 where ``share`` > 0).
    """

    dof: float
    share: float = 0.0
    mean: float = 1.0

    def __post_init__(self):
        if not 0.0 <= self.share < 1.0 or not self.mean > 0.0 or not self.dof > 0.0:
            raise ValueError(f"arrival model: delay share {self.share} (allowed [0, 1)), mean delay {self.mean} σ "
                             f"and ν {self.dof} (allowed > 0)")

    def _parts(self, z: np.ndarray) -> tuple:
        """γ, δ̂, var δ, the Student-t weight w_t, the half gradient g and ``ln p(z) − ln((1 − π) t_ν(0))`` at the
        normalised residuals z."""
        nu, lam = self.dof, self.mean
        w_t = (nu + 1.0) / (nu + z**2)
        log_t = -0.5 * (nu + 1.0) * np.log1p(z**2 / nu)  # ln(t_ν(z) / t_ν(0))
        m = z - 1.0 / lam
        log_phi_m = log_ndtr(m)
        log_t0 = gammaln((nu + 1) / 2) - gammaln(nu / 2) - 0.5 * np.log(nu * np.pi)
        log_f = -np.log(lam) + 0.5 / lam**2 - z / lam + log_phi_m - log_t0  # ln(f(z) / t_ν(0))
        b = np.log(self.share / (1.0 - self.share)) + log_f if self.share > 0.0 else np.full_like(log_f, -np.inf)
        log_p = np.logaddexp(log_t, b)  # ln(p(z) / ((1 − π) t_ν(0)))
        gamma = np.exp(b - log_p)
        mills = np.exp(-0.5 * m**2 - _LOG_SQRT_2PI - log_phi_m)
        delay = m + mills
        var = np.maximum(1.0 - mills * (m + mills), 0.0)
        g = (1.0 - gamma) * w_t * z + gamma * (z - delay)
        return gamma, delay, var, w_t, g, log_p

    def terms(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each arrival's cost term, EM weight and half gradient at the normalised residuals z.

        Parameters
        ----------
        z : ndarray, (h,)
            Normalised residuals ``(toa − t_e − ρ / c) / σ_toa`` [1].

        Returns
        -------
        cost : ndarray, (h,)
            ``−2 ln p(z) + 2 ln((1 − π) t_ν(0))`` [1] (``(ν + 1) ln(1 + z²/ν)`` at π = 0).
        h : ndarray, (h,)
            The EM weight ``(1 − γ) w_t + γ`` [1].
        g : ndarray, (h,)
            The half gradient of the cost in z, ``(1 − γ) w_t z + γ (z − δ̂)`` [1].
        """
        gamma, _, _, w_t, g, log_p = self._parts(np.asarray(z, float))
        return -2.0 * log_p, (1.0 - gamma) * w_t + gamma, g

    def information(self, z: np.ndarray) -> np.ndarray:
        """Each arrival's observed information, ``−(ln p)''(z)`` [1], 0 where negative (as the Student-t's,
        :func:`~sblsim.models.tracking.smoother_cost.observed_information`).

        ``−(ln p)'' = (p'/p)² − p''/p``, with ``p'/p = −g`` and ``p''/p = (1 − γ) t''/t + γ f''/f``,
        ``t''/t = (w_t z)² − (ν + 1)(ν − z²)/(ν + z²)²`` and ``f''/f = (z − δ̂)² + var δ − 1``.

        Parameters
        ----------
        z : ndarray, (h,)

        Returns
        -------
        ndarray, (h,)
        """
        z = np.asarray(z, float)
        nu = self.dof
        gamma, delay, var, w_t, g, _ = self._parts(z)
        t2 = (w_t * z) ** 2 - (nu + 1.0) * (nu - z**2) / (nu + z**2) ** 2
        f2 = (z - delay) ** 2 + var - 1.0
        return np.maximum(g**2 - ((1.0 - gamma) * t2 + gamma * f2), 0.0)


__all__ = ["ArrivalModel"]
