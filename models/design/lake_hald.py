"""The telemetry criteria of a receiver layout over a study area, and the Lake Hald array evaluated with them: the
groundwork of the worked case of a telemetry array's design.

:func:`evaluate_layout` maps a layout's positioning yield, its DRMS (averaged information and the RMS over fixed
pings, :mod:`sblsim.models.design.telemetry`) and its sync coverage over a grid of an area's points.

**Lake Hald** (Baktoft, Gjelland, Økland, Thygesen, Scientific Reports 7:14294, 2017; the repository's
``data/lake-hald/``): 27 hydrophones in the lake's local frame (H1 at the origin; no depths: 2-D). Stated here:

* :data:`LAKE_HALD_AREA`, the study area, is **a polygon drawn by hand around the hydrophones' area** (about 20–40
  m beyond the outermost hydrophones, 41,600 m²), not the lake's shoreline, which the data do not hold;
* :data:`LAKE_HALD_DETECTION`, the detection range curve, is a table read off the tow's own record: each ping's
  first arrival timed against the boat's GPS, the share of hydrophones that heard it in 25 m bins of distance
  (0.45 to 50 m, 0.37 at 75–100 m, 0.23 at 125–175 m, 0.08–0.14 at 200–250 m, 0 beyond 300 m), rounded into a
  non-increasing table: a towed transmitter's, of pings heard by at least one hydrophone, the GPS's lever arm to
  the transmitter unrecorded; a fish tag's range test would give its own;
* the tag: a random burst interval of 20–40 s (:data:`LAKE_HALD_TAG`). A single ping's criteria do not depend on
  the interval; the smoothed track's bound does (phase of the design that uses the tracker's bound);
* the timing: σ_toa = 0.15 ms (the tracker's default for recorded arrivals) at 1,420 m/s (close to the sound
  speed the tracker fits to the tow, 1,416.9 m/s): σ₀ = 0.213 m, constant with range;
* the sync tags: one at each hydrophone, heard with the same curve; a link counts where it is heard with
  probability at least :data:`LAKE_HALD_SYNC_P` per sync ping (sync tags ping often, so a low per-ping probability
  still times the clocks).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.design import area as areas
from sblsim.models.design import sync_graph as sg
from sblsim.models.design import telemetry as tm
from sblsim.models.design.detection_curve import DetectionCurve
from sblsim.models.errors import ModelError

#: The study area drawn by hand around Lake Hald's hydrophones (x, y) [m] (module docstring: not the shoreline).
LAKE_HALD_AREA = ((-165.0, -60.0), (-150.0, 20.0), (-120.0, 60.0), (-60.0, 50.0), (25.0, 20.0), (75.0, 5.0),
                  (135.0, -30.0), (175.0, -80.0), (100.0, -150.0), (40.0, -125.0), (-40.0, -95.0), (-135.0, -90.0))
#: The detection range curve read off the tow's record: rows (distance [m], probability) (module docstring).
LAKE_HALD_DETECTION = ((0.0, 0.45), (50.0, 0.45), (100.0, 0.35), (150.0, 0.23), (200.0, 0.12), (250.0, 0.05),
                       (300.0, 0.0))
#: The tag: ping type and burst interval bounds [s].
LAKE_HALD_TAG = ("rbi", 20.0, 40.0)
#: Timing [s] and sound speed [m/s].
LAKE_HALD_SIGMA_TOA = 1.5e-4
LAKE_HALD_SOUND_SPEED = 1420.0
#: The per-ping probability a sync link needs [0–1].
LAKE_HALD_SYNC_P = 0.2


@dataclass(frozen=True)
class LayoutEvaluation:
    """A layout's telemetry criteria over an area's points (:func:`evaluate_layout`).

    Attributes
    ----------
    points : ndarray, shape (M, 2)
        [m].
    positioning_yield : ndarray, shape (M,)
        [0–1].
    drms_expected : ndarray, shape (M,)
        DRMS of the averaged information [m].
    drms_fixed : ndarray, shape (M,)
        RMS over the fixed pings [m] (``inf``: none).
    fixable : ndarray, shape (M,)
        Probability a ping is fixed [0–1].
    sync : SyncCoverage
    """

    points: np.ndarray
    positioning_yield: np.ndarray
    drms_expected: np.ndarray
    drms_fixed: np.ndarray
    fixable: np.ndarray
    sync: sg.SyncCoverage

    def coverage(self, drms_m: float, yield_min: float, fixed: bool = True) -> float:
        """The share of the points [%] with a DRMS (``fixed``: the RMS over fixed pings; else the averaged
        information's) of at most ``drms_m`` [m] and a yield of at least ``yield_min`` [0–1]."""
        value = self.drms_fixed if fixed else self.drms_expected
        return 100.0 * float(np.mean((value <= drms_m) & (self.positioning_yield >= yield_min)))

    def lines(self, drms_m: float = 1.0, yield_min: float = 0.8) -> list[str]:
        """The numbers in a few lines of text."""
        y, fe, ff = self.positioning_yield, self.drms_expected, self.drms_fixed

        def pct(a, q):
            return float(np.percentile(np.where(np.isfinite(a), a, np.inf), q, method="higher"))
        return [
            f"points: {len(y)}",
            f"positioning yield: median {np.median(y):.3f}, 10th percentile {np.percentile(y, 10):.3f}, "
            f"share >= {yield_min:g}: {100 * np.mean(y >= yield_min):.1f} %",
            f"DRMS, averaged information [m]: median {np.median(fe):.3f}, p90 {pct(fe, 90):.3f}",
            f"DRMS, RMS over fixed pings [m]: median {np.median(ff):.3f}, p90 {pct(ff, 90):.3f}",
            f"share with DRMS <= {drms_m:g} m and yield >= {yield_min:g}: {self.coverage(drms_m, yield_min):.1f} % "
            f"(fixed pings), {self.coverage(drms_m, yield_min, fixed=False):.1f} % (averaged information)",
            f"sync: receivers hearing >= {sg.SYNC_NEEDED} sync tags {100 * float(self.sync.share):.0f} %, "
            f"components {int(self.sync.components)}, met {bool(self.sync.met)}",
        ]


def evaluate_layout(receivers: np.ndarray, area, curve: DetectionCurve, sigma0_m: float, per_m: float = 0.0,
                    spacing_m: float = 10.0, sync_p: float = 0.5, samples: int = 400,
                    rng: np.random.Generator | None = None) -> LayoutEvaluation:
    """A layout's criteria over an area's grid, 2-D, no depth sensor (a fix needs 3 receivers).

    Parameters
    ----------
    receivers : ndarray, shape (n, 2)
        [m].
    area : array_like or shapely Polygon
        The study area (:func:`~sblsim.models.design.area.polygon`).
    curve : DetectionCurve
    sigma0_m, per_m : float
        The timing law :func:`~sblsim.models.design.telemetry.range_sigma` [m], [1].
    spacing_m : float, optional
        The grid's [m].
    sync_p : float, optional
        The probability a sync link needs.
    samples : int, optional
        Monte Carlo patterns per point where the enumeration does not reach.
    rng : numpy.random.Generator, optional

    Returns
    -------
    LayoutEvaluation

    Raises
    ------
    ModelError
        A bad area, a receiver outside it, or bad numbers.
    """
    polygon = areas.polygon(area)
    receivers = np.asarray(receivers, float)
    outside = np.flatnonzero(~areas.inside(polygon, receivers))
    if len(outside):
        raise ModelError(f"receivers: {len(outside)} outside the study area (the first at "
                            f"{receivers[outside[0]].tolist()} m); allowed inside site.area")
    points = areas.grid(polygon, spacing_m)
    d = tm.distances(points, receivers)
    q = curve.probability(d)
    sigma = tm.range_sigma(d, sigma0_m, per_m)
    drms_fixed, fixable = tm.fixed_ping_drms(points, receivers, sigma, q, rng, samples)
    sync = sg.sync_coverage(sg.sync_probabilities(receivers, curve.probability), sync_p)
    return LayoutEvaluation(points, tm.positioning_yield(q, 3),
                            tm.expected_information_drms(points, receivers, sigma, q), drms_fixed, fixable, sync)


def lake_hald_evaluation(hydrophones: np.ndarray, spacing_m: float = 10.0, samples: int = 400,
                         rng: np.random.Generator | None = None) -> LayoutEvaluation:
    """The authors' Lake Hald layout evaluated with the stated area, curve, tag and timing (module docstring).

    Parameters
    ----------
    hydrophones : ndarray, shape (n, 2)
        The hydrophones' x, y [m] (``data/lake-hald/hydrophones.csv``'s, the failed one left out).
    spacing_m, samples, rng
        As :func:`evaluate_layout`.

    Returns
    -------
    LayoutEvaluation
    """
    rows = np.asarray(LAKE_HALD_DETECTION)
    curve = DetectionCurve.table(rows[:, 0], rows[:, 1])
    return evaluate_layout(hydrophones, LAKE_HALD_AREA, curve, LAKE_HALD_SOUND_SPEED * LAKE_HALD_SIGMA_TOA,
                           spacing_m=spacing_m, sync_p=LAKE_HALD_SYNC_P, samples=samples, rng=rng)


__all__ = ["LAKE_HALD_AREA", "LAKE_HALD_DETECTION", "LAKE_HALD_SOUND_SPEED", "LAKE_HALD_SIGMA_TOA", "LAKE_HALD_SYNC_P",
           "LAKE_HALD_TAG", "LayoutEvaluation", "evaluate_layout", "lake_hald_evaluation"]
