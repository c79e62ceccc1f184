"""The criteria a design is judged by over a work area, its coverage of a prescription, and the closed forms of
the optimal geometries.

At each point p of a work area a layout gives the Fisher information J(p) of one cycle
(:func:`~sblsim.models.design.information.layout_information`): its horizontal DRMS
``sqrt((J⁻¹)_NN + (J⁻¹)_EE)`` (or the 3-D ``sqrt(tr J⁻¹)``) and ``log det J``. A criterion turns the points'
numbers into one number to minimise (:func:`criterion`):

* ``percentile``: the P-th percentile of the DRMS over the area (P the prescription's coverage): the prescription
  itself, "DRMS ≤ X at P % of the work area", is met if and only if it is at most X;
* ``d-optimal``: minus the mean of ``log det J`` (D-optimality: the volume of the error ellipsoid);
* ``a-optimal``: the mean of the squared DRMS (A-optimality: the trace of the Cramér-Rao bound, of its
  horizontal block for a horizontal prescription);
* ``worst``: the largest DRMS over the area (minimax).

A point where no fix is made (the map's blank, NaN) counts as an infinite DRMS and an information of zero. So does,
for the coverage and the ``percentile`` and ``worst`` criteria, a point whose fix takes a range of reflections in
more than :data:`ECHO_LIMIT` of the cycles (the first detected arrival of a transducer is a surface or bottom
reflection there): the Fisher information of the direct rays does not describe that fix.

Closed forms (range-only measurements of one standard deviation σ, no depth sensor; Bishop, Fidan, Anderson,
Doğançay, Pathirana, "Optimality analysis of sensor-target localization geometries", Automatica 46(3):479-492,
2010):

* in 2-D, N ≥ 3 sensors at bearings θ_k around a target: ``det J = (N² − |Σ_k e^{2iθ_k}|²) / (4σ⁴)``, at most
  ``N² / (4σ⁴)`` (:func:`bishop_2d_determinant`), reached if and only if ``Σ_k e^{2iθ_k} = 0``, where J is
  ``N / (2σ²) I`` and the Cramér-Rao bound's trace ``4σ² / N`` (:func:`bishop_2d_crb_trace`), its minimum;
* in 3-D, N ≥ 3 transponders equally spaced on a ring at height h below the target: D- and A-optimal at the
  ring radius ``√2 h`` (:data:`RING_RADIUS_RATIO`; the lines of sight at :data:`RING_ELEVATION_DEG` below the
  horizontal), where ``det J = (N / 3)³ / σ⁶`` (:func:`ring_determinant`) and ``tr J⁻¹ = 9σ² / N``
  (:func:`ring_crb_trace`; a PDOP of 1.5 at N = 4).
"""

from __future__ import annotations

import math

import numpy as np

#: The criteria of a design: name -> what it minimises.
CRITERIA = {
    "percentile": "the DRMS at the prescription's coverage (its percentile over the work area) [m]",
    "d-optimal": "minus the mean log det J over the work area (D-optimality)",
    "a-optimal": "the mean squared DRMS over the work area (A-optimality: the trace of the Cramér-Rao bound) [m²]",
    "worst": "the largest DRMS over the work area [m]",
}
#: The largest probability that a cycle's fix takes a range of reflections at a point the prediction holds for [1].
ECHO_LIMIT = 0.01
#: The largest margin from :data:`ECHO_LIMIT` a prescription may keep, in percentage points [%] (below the limit's
#: own 1 %: a margin of 1 would leave no probability of reflections at all).
MAX_ECHO_MARGIN_PCT = 0.99
#: The prescription's dimensions: horizontal (the DRMS of North and East) or 3d (North, East and Down).
DIMENSIONS = ("horizontal", "3d")
#: The 3-D ring's optimal radius over the height below the target [1].
RING_RADIUS_RATIO = math.sqrt(2.0)
#: The optimal ring's lines of sight below the horizontal [deg]: atan(1/√2), 35.2644°.
RING_ELEVATION_DEG = math.degrees(math.atan(1.0 / math.sqrt(2.0)))
#: The D-optimal ring's radius over its height where each range's σ is proportional to it [1]: 1/√2, 0.7071
#: (:func:`ring_noise_drms`).
RING_RATIO_PROPORTIONAL = 1.0 / math.sqrt(2.0)


def criterion(name: str, drms: np.ndarray, log_det: np.ndarray, coverage_pct: float,
              echo: np.ndarray | None = None) -> np.ndarray:
    """The criterion ``name`` (:data:`CRITERIA`) of one or more layouts over a work area, to be minimised.

    Parameters
    ----------
    name : str
        One of :data:`CRITERIA`.
    drms : ndarray, shape (..., M)
        The DRMS (horizontal or 3-D, as the prescription's dimensions) at the M points [m]; NaN where no fix.
    log_det : ndarray, shape (..., M)
        ``log det J`` at the points; NaN where no fix.
    coverage_pct : float
        The prescription's coverage P [%], the percentile of ``percentile``.
    echo : ndarray, shape (..., M), optional
        The probability that a point's fix takes a range of reflections [0–1]; above :data:`ECHO_LIMIT` the
        point counts as without a fix (``percentile``, ``worst``).

    Returns
    -------
    ndarray, shape (...)
        [m] for ``percentile`` and ``worst``, [m²] for ``a-optimal``, [1] for ``d-optimal``.

    Raises
    ------
    ValueError
        For an unknown criterion.
    """
    drms = np.where(np.isfinite(drms), drms, np.inf)
    if echo is not None and name in ("percentile", "worst"):
        drms = np.where(echo > ECHO_LIMIT, np.inf, drms)
    if name == "percentile":
        return np.percentile(drms, coverage_pct, axis=-1, method="higher")
    if name == "worst":
        return drms.max(axis=-1)
    if name == "a-optimal":
        return np.mean(drms ** 2, axis=-1)
    if name == "d-optimal":
        return -np.mean(np.where(np.isfinite(log_det), log_det, -np.inf), axis=-1)
    raise ValueError(f"criterion: {name!r} is not one of {', '.join(CRITERIA)}")


def coverage(drms: np.ndarray, availability: np.ndarray, drms_m: float, availability_pct: float,
             echo: np.ndarray | None = None) -> np.ndarray:
    """The share of a work area's points that meet a prescription [%]: DRMS at most ``drms_m`` [m], a fix in at
    least ``availability_pct`` [%] of the cycles and, with ``echo``, ranges of reflections in at most
    :data:`ECHO_LIMIT` of them.

    Parameters
    ----------
    drms, availability : ndarray, shape (..., M)
        [m] (NaN: no fix) and the probability of a fix in one cycle [0–1].
    drms_m, availability_pct : float
    echo : ndarray, shape (..., M), optional
        The probability that a cycle's fix takes a range of reflections [0–1].

    Returns
    -------
    ndarray, shape (...)
    """
    met = np.isfinite(drms) & (np.nan_to_num(drms, nan=np.inf) <= drms_m) & \
        (availability >= availability_pct / 100.0 - 1e-12)
    if echo is not None:
        met &= echo <= ECHO_LIMIT
    return 100.0 * met.mean(axis=-1)


def judged_echo(echo: np.ndarray, margin_pct: float = 0.0) -> np.ndarray:
    """The probability that a point's fix takes a range of reflections on the scale of :data:`ECHO_LIMIT`, with a
    margin from it: a point counts only where its probability is at most ``ECHO_LIMIT − margin`` (the direct
    arrival heard first with that margin), that is where the value returned is at most :data:`ECHO_LIMIT`.

    ``echo · ECHO_LIMIT / (ECHO_LIMIT − margin)``: every comparison with :data:`ECHO_LIMIT` (:func:`criterion`,
    :func:`coverage`, a design's checked points and its share of points failing for reflections) then applies the
    margin; a margin of 0 returns ``echo`` itself (the same array, bit for bit).

    Parameters
    ----------
    echo : ndarray, shape (...)
        The probability that a cycle's fix takes a range of reflections [0–1].
    margin_pct : float, optional
        The margin [%, percentage points of probability], in [0, :data:`MAX_ECHO_MARGIN_PCT`].

    Returns
    -------
    ndarray, shape (...)
        [1], the probability scaled by ``ECHO_LIMIT / (ECHO_LIMIT − margin)`` (it may exceed 1: only its
        comparison with :data:`ECHO_LIMIT` means something).

    Raises
    ------
    ValueError
        For a margin outside [0, :data:`MAX_ECHO_MARGIN_PCT`] %.
    """
    if not 0.0 <= margin_pct <= MAX_ECHO_MARGIN_PCT:
        raise ValueError(f"echo margin: {margin_pct!r} %; allowed [0, {MAX_ECHO_MARGIN_PCT:g}] %")
    if margin_pct == 0.0:
        return echo
    return np.asarray(echo, dtype=float) * (ECHO_LIMIT / (ECHO_LIMIT - margin_pct / 100.0))


def ring_noise_drms(n: int, radius: float, height: float, sigma0: float, per_m: float = 0.0,
                    horizontal: bool = True) -> float:
    """The DRMS at the centre of N ≥ 3 transponders equally spaced on a ring of ``radius`` at ``height`` below
    (or above) the point, every range of the standard deviation ``σ = σ₀ + k ρ`` at the slant range
    ``ρ = √(r² + h²)`` (:func:`sblsim.models.design.information.range_noise_variance`), no depth sensor [m].

    Every range has the same σ, so the ring's closed form holds with σ at the ring's slant range: the lines of
    sight ``(r cos θ, r sin θ, h) / ρ`` give ``J = N / (σ² ρ²) diag(r² / 2, r² / 2, h²)``, the horizontal DRMS
    ``2 σ ρ / (r √N)`` and the 3-D ``σ ρ √(4 / r² + 1 / h²) / √N``. With ``σ₀ = 0`` (σ ∝ range), ``det J ∝
    r⁴ h² / ρ¹²``, largest at ``r / h = 1 / √2`` (:data:`RING_RATIO_PROPORTIONAL`; the constant σ's √2,
    :data:`RING_RADIUS_RATIO`, otherwise).

    Parameters
    ----------
    n : int
    radius, height : float
        [m], positive (the height: any sign).
    sigma0 : float
        [m].
    per_m : float, optional
        [m/m].
    horizontal : bool, optional
        The horizontal DRMS (else the 3-D).

    Returns
    -------
    float
        [m].
    """
    rho = math.hypot(radius, height)
    sigma = sigma0 + per_m * rho
    if horizontal:
        return 2.0 * sigma * rho / (radius * math.sqrt(n))
    return sigma * rho * math.sqrt(4.0 / radius ** 2 + 1.0 / height ** 2) / math.sqrt(n)


def bishop_2d_determinant(n: int, sigma: float) -> float:
    """The largest ``det J`` of N range sensors around a target in 2-D, ``N² / (4σ⁴)`` [1/m⁴] (Bishop et al. 2010)."""
    return n ** 2 / (4.0 * sigma ** 4)


def bishop_2d_crb_trace(n: int, sigma: float) -> float:
    """The smallest trace of the Cramér-Rao bound of N range sensors in 2-D, ``4σ² / N`` [m²] (Bishop et al.
    2010)."""
    return 4.0 * sigma ** 2 / n


def ring_determinant(n: int, sigma: float) -> float:
    """``det J`` of N transponders equally spaced on a ring of radius √2 h at height h below the target,
    ``(N / 3)³ / σ⁶`` [1/m⁶]."""
    return (n / 3.0) ** 3 / sigma ** 6


def ring_crb_trace(n: int, sigma: float) -> float:
    """``tr J⁻¹`` of the optimal ring, ``9σ² / N`` [m²] (a PDOP of 1.5 at N = 4)."""
    return 9.0 * sigma ** 2 / n


__all__ = ["CRITERIA", "DIMENSIONS", "ECHO_LIMIT", "MAX_ECHO_MARGIN_PCT", "RING_ELEVATION_DEG", "RING_RADIUS_RATIO",
           "RING_RATIO_PROPORTIONAL", "bishop_2d_crb_trace", "bishop_2d_determinant", "coverage", "criterion",
           "judged_echo", "ring_crb_trace", "ring_determinant", "ring_noise_drms"]
