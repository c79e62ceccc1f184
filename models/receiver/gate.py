"""The NIS gate of the Kalman-type receivers: its parameters, its χ² threshold and the test.

A fresh scalar measurement of innovation ``y`` and innovation variance
``S = H P Hᵀ + R`` has the normalized innovation squared ``NIS = y² / S``,
χ²-distributed with one degree of freedom when the filter is consistent.
The gate refuses a measurement whose NIS exceeds the χ²(1) quantile of the
gate probability (:func:`gate_threshold`), one-sided for ranges (a late
multipath arrival is long, never short), with a re-acquisition that tests the
range itself against the lock-out (:func:`gate`).

References
----------
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation, Wiley 2001, Section 5.4 (NIS and its χ² test). Winitzki, "A
handy approximation for the error function and its inverse", 2008 (the
starting point of :func:`erfinv`).
"""

from __future__ import annotations

import math

import casadi as ca

from sblsim.models.declarations import Variable
from sblsim.models.expressions import only_where, select


def gate_parameters(probability: float) -> tuple[Variable, ...]:
    """The NIS gate: the probability a correct range passes it (1: no gate), and its lockout guard."""
    return (
        Variable("gate_probability", "parameter", "Real", probability, "1",
                 "NIS gate on long ranges: probability that a correct range passes (chi-square, 1 dof); 1: no gate",
                 min=0.5, max=1.0),
        Variable("gate_max_rejections", "parameter", "Integer", 2,
                 description="NIS gate: when this many beacons' latest ranges failed the test, a failing range "
                             "that agrees with its beacon's previous failing one is used (re-acquisition, no "
                             "lock-out)", min=1, max=1000),
    )


def erfinv(y) -> ca.SX:
    """Inverse error function for 0 ≤ y < 1 as a plain expression (the generated C has no ``erfinv``).

    Winitzki's closed-form approximation (relative error about 2·10⁻³) refined
    by three Newton steps on ``erf``: about 10⁻¹⁴ relative for y ≤ 1 − 10⁻⁴.
    """
    a = 0.147
    log_term = ca.log(1.0 - y * y)
    t = 2.0 / (math.pi * a) + 0.5 * log_term
    x = ca.sqrt(ca.sqrt(t * t - log_term / a) - t)
    for _ in range(3):
        x = x - (ca.erf(x) - y) * (0.5 * math.sqrt(math.pi)) * ca.exp(x * x)
    return x


def gate_threshold(probability) -> ca.SX:
    """χ²(1) quantile of ``probability``: ``2 erfinv(probability)²``; infinite (no gate) for probability ≥ 1."""
    q = 2.0 * erfinv(ca.fmin(probability, 1.0 - 1e-12)) ** 2
    return ca.if_else(probability >= 1.0, ca.inf, q)


def gate(innovation, variance, fresh, x: dict, u: dict, p: dict, earlier=None) -> dict[str, ca.SX]:
    """The NIS gate on a fresh range of innovation ``innovation`` [m] and innovation variance ``variance`` [m²].

    A fresh range passes the test when it is not longer than predicted
    (multipath and non-line-of-sight arrivals are late: the direct path is the
    shortest) or its NIS ``innovation² / variance`` is within the χ²(1)
    quantile of ``gate_probability``; each beacon remembers whether its latest
    range failed. A multipath outlier is isolated, but when the estimate has
    drifted (a sudden turn, a long loss, a mirror solution) the ranges of
    several beacons fail together, and a gate that kept rejecting them would
    never recover (gate lock-out). So when at least ``gate_max_rejections``
    beacons' latest ranges failed (or every beacon's, when the interface has
    fewer: a USBL interface has one, its transceiver), a range that fails is
    **re-acquired** if it agrees with its own beacon's previous range, which
    failed too: both predicted from the current state, their innovations must
    differ by no more than the χ²(1) quantile allows for the sum of their
    innovation variances (``earlier``). A drifted estimate misses two
    consecutive ranges of a beacon alike; a multipath outlier's random excess
    makes it disagree with the range before it, so it is not let in to
    re-acquire (the consistency of consecutive ranges: Olson, Leonard, Teller
    2006).

    Parameters
    ----------
    innovation, variance, fresh : casadi.SX
        The range's innovation, its innovation variance and whether there is a fresh range at all.
    x : dict
        The receiver's state blocks; ``failed`` (n, 1) is read.
    u : dict
        The inputs; ``beacon_id`` is read.
    p : dict
        The parameters ``gate_probability`` and ``gate_max_rejections`` (:func:`gate_parameters`).
    earlier : tuple of casadi.SX, optional
        ``(innovation, variance)`` of the fresh beacon's previous failed range predicted from the current state
        (:func:`sblsim.models.receiver.reacquisition.earlier_innovation`); None: nothing is re-acquired.

    Returns
    -------
    dict
        ``use`` (update with the range), ``gated`` (rejected), ``failed``
        (n: each beacon's latest test failed, after this slot) and ``rejecting`` (the fresh range failed its
        test: the one to remember for the next re-acquisition).

    References
    ----------
    Olson, Leonard, Teller, "Robust range-only beacon localization", IEEE Journal of Oceanic Engineering 31(4),
    2006 (consistency of ranges against outliers).
    """
    threshold = gate_threshold(p["gate_probability"])
    test = ca.logic_or(innovation <= 0.0, innovation * innovation / variance <= threshold)
    beacons = x["failed"].numel()
    guard = ca.sum1(x["failed"]) >= ca.fmin(p["gate_max_rejections"], beacons)  # fewer beacons: all of them failed
    index = u["beacon_id"] - 1
    if earlier is None:
        again = 0
    else:  # the beacon's own previous range failed too, and the two agree
        before, spread = earlier
        own = select(index, [x["failed"][j] for j in range(beacons)]) > 0.5
        # read only for a fresh range that fails its test in a lock-out, and computed only there (a run without a
        # gate never computes the earlier range's innovation)
        again = only_where("sblsim_gate_again", ca.logic_and(fresh, ca.logic_and(guard, ca.logic_not(test))),
                           lambda y, s, q: ca.logic_and(own, (y - before) ** 2 <= q * (s + spread)),
                           innovation, variance, threshold)
    use = ca.logic_and(fresh, ca.logic_or(test, ca.logic_and(guard, again)))
    failed = ca.vertcat(*[ca.if_else(ca.logic_and(fresh, index == j), ca.logic_not(test), x["failed"][j])
                          for j in range(beacons)])
    return {"use": use, "gated": ca.logic_and(fresh, ca.logic_not(use)), "failed": failed,
            "rejecting": ca.logic_and(fresh, ca.logic_not(test))}


__all__ = ["erfinv", "gate", "gate_parameters", "gate_threshold"]
