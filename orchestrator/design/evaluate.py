"""The design's evaluation of candidate layouts over a work area: the accuracy map's numbers, fast.

A candidate is judged by the Fisher information of one cycle at every work-area point, the same as the map's
(:func:`sblsim.orchestrator.maps.point_accuracy`): the layout's information
(:func:`sblsim.models.design.information.layout_information`) with the plan's error levels, each transducer's range
weighted by the probability that it is heard and its noise grown with its SNR. A search evaluates thousands of
layouts, so:

* the layout function runs compiled (:func:`sblsim.fmus.compiled_functions.compiled_layout`: the generated C of the
  same casadi function, called on numpy arrays, a few hundred microseconds for a layout over 441 points), casadi's own
  evaluation where no compiler is found;
* the site's detection is tabulated once (:class:`Detection`): the site is range-independent, so what a
  transducer at the seafloor's depth makes of a vehicle at a work-area depth depends on their horizontal distance
  alone; the search interpolates that table, and every design it proposes is evaluated again through the map
  itself (:func:`~sblsim.orchestrator.maps.point_accuracy`), whose numbers the outputs carry.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from sblsim.fmus.compiled_functions import compiled_layout
from sblsim.fmus.library_sources import LAYOUT_CHUNK
from sblsim.models.design.criteria import judged_echo
from sblsim.models.design.information import OUTPUTS, law_range_variance, layout_values, padded, slots_for
from sblsim.models.target.core import Target
from sblsim.orchestrator.cosim.plan import RunPlan
from sblsim.orchestrator.maps import MIN_AVAILABILITY, fix_probability, grown_noise, packet_probabilities

#: The step of a detection table [m].
TABLE_STEP = 5.0
#: A vehicle without a depth sensor (``work_area.depth_sensor = false``): its scenario's depth sensor at the largest
#: standard deviation ``target.depth_sigma`` takes [m] (1000 m: an information of 1e-6 /m² about the depth, which
#: moves a fix of ranges by a relative 1e-6 or less; the map, the search and the Monte Carlo's receiver all take it).
NO_DEPTH_SIGMA = float(next(v.max for v in Target.variables() if v.name == "depth_sigma"))


def problem_items(sections: dict, plan: RunPlan) -> list[str]:
    """The overrides of the base scenario that a design problem's own keys make (each design's scenario carries
    them, as the search, the map and the Monte Carlo do).

    * ``work_area.depth_sensor = false``: ``target.depth_sigma`` at :data:`NO_DEPTH_SIGMA`;
    * the work area's depth: ``target.depth`` the first of ``work_area.depths_m`` where it differs from the
      scenario's and its trajectory takes a depth (not a file's waypoints), so that the design's scenario (and its
      map, drawn at ``target.depth`` by default) is at the work area's depth;
    * ``detection.range_k`` > 0: ``acoustics.range_k`` (the range law, :mod:`sblsim.models.acoustics.range_law`),
      which the channel draws, the receivers weigh and the map and the search predict.

    Parameters
    ----------
    sections : dict
        The checked problem (``work_area.depths_m`` resolved: never empty).
    plan : RunPlan
        The base scenario's plan.

    Returns
    -------
    list of str
        ``section.key=value`` items (empty where the problem's keys ask nothing of the scenario).
    """
    work = sections["work_area"]
    items = []
    if not work.get("depth_sensor", True):
        items.append(f"target.depth_sigma={NO_DEPTH_SIGMA!r}")
    target = plan["target"]
    depth = float(work["depths_m"][0])
    if target.get("trajectory") != "file" and float(target["depth"]) != depth:
        items.append(f"target.depth={depth!r}")
    range_k = float(sections.get("detection", {}).get("range_k", 0.0))
    if range_k > 0.0 and float(plan["acoustics"].get("range_k", 0.0)) != range_k:
        items.append(f"acoustics.range_k={range_k!r}")
    return items


@dataclass(frozen=True)
class Levels:
    """A system's error levels for the layout function, from a plan (:attr:`RunPlan.bound`).

    Attributes
    ----------
    noise_variance : float
        A range's variance with the transducer position's error folded in, σ_r² + σ_pos² [m²].
    range_variance : float
        σ_r², the part that grows below the reference SNR [m²].
    attitude_variance, depth_variance : float
        [rad²], [m²] (``inf``: no depth sensor).
    fix_packets : int
        The packets of one cycle a fix needs.
    range_k : float
        The range law's growth [m/m] (``acoustics.range_k``; 0: the constant σ_r).
    """

    noise_variance: float
    range_variance: float
    attitude_variance: float
    depth_variance: float
    fix_packets: int = 3
    range_k: float = 0.0

    @classmethod
    def of(cls, plan: RunPlan) -> Levels:
        bound = plan.bound
        return cls(bound["noise_variance"], plan["acoustics"]["sigma_range"] ** 2, bound["attitude_variance"],
                   bound["depth_variance"], plan.system.fix_packets, float(plan["acoustics"].get("range_k", 0.0)))

    def noise(self, points: np.ndarray, layouts: np.ndarray) -> tuple[np.ndarray | float, np.ndarray | float]:
        """Each range's variance with the position error folded in and its own part [m²], per layout, point and
        transducer (S, M, n) with the range law (:func:`~sblsim.models.design.information.law_range_variance`),
        else the constant :attr:`noise_variance` and :attr:`range_variance`."""
        if self.range_k == 0.0:
            return self.noise_variance, self.range_variance
        sigma = float(np.sqrt(self.range_variance))
        own = law_range_variance(points, layouts, sigma, self.range_k)
        return self.noise_variance - self.range_variance + own, own


def judged(values: dict, sections: dict) -> dict:
    """A map's values (:func:`~sblsim.orchestrator.maps.point_accuracy`'s) with ``echo`` judged with the
    prescription's margin from the echo limit (``prescription.echo_margin_pct``,
    :func:`~sblsim.models.design.criteria.judged_echo`); the same dict where the margin is 0."""
    margin = sections["prescription"]["echo_margin_pct"]
    return values if margin == 0.0 else {**values, "echo": judged_echo(values["echo"], margin)}


class Detection:
    """What the site makes of a transducer at one depth and a vehicle at each work-area depth, as functions of
    their horizontal distance: the packet's probability of being heard and its accuracy scale
    (:func:`~sblsim.orchestrator.maps.packet_probabilities`), tabulated every :data:`TABLE_STEP` and interpolated
    linearly.

    Parameters
    ----------
    plan : RunPlan
        The site (a plan of the system, its channel and detection).
    transducer_depth : float
        The transducers' depth [m] (the seafloor's for an LBL; the platform's transducer depth otherwise).
    depths : sequence of float
        The vehicle's depths [m].
    reach : float
        The longest horizontal distance asked for [m].
    """

    def __init__(self, plan: RunPlan, transducer_depth: float, depths, reach: float) -> None:
        self.snr = plan["acoustics"]["detection"] == "snr"
        self.depths = np.asarray(depths, dtype=float)
        self.distance = np.arange(0.0, reach + 2.0 * TABLE_STEP, TABLE_STEP)
        transducer = np.array([[0.0, 0.0, float(transducer_depth)]])
        self.columns = []  # per depth: the probability, the scale, the probability of a range of reflections
        for depth in self.depths:
            points = np.column_stack([self.distance, np.zeros_like(self.distance),
                                      np.full_like(self.distance, depth)])
            self.columns.append([c[:, 0] for c in packet_probabilities(plan, points, transducer, echo=True)])

    def __call__(self, points: np.ndarray, layouts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each packet's probability of being heard, its accuracy scale and the probability that its range is of
        reflections, between vehicles at ``points`` (M, 3) (at the table's depths) and the transducers of S layouts
        (S, n, 3), NED [m]; each (S, M, n)."""
        horizontal = np.hypot(points[None, :, None, 0] - layouts[:, None, :, 0],
                              points[None, :, None, 1] - layouts[:, None, :, 1])
        out = tuple(np.empty(horizontal.shape) for _ in range(3))
        for k, depth in enumerate(self.depths):
            rows = np.isclose(points[:, 2], depth)
            # the table's nodes are evenly spaced: the interval and the weight of each distance without a search
            x = np.minimum(horizontal[:, rows] / TABLE_STEP, len(self.distance) - 1.0)
            below = np.minimum(x.astype(np.int64), len(self.distance) - 2)
            weight = x - below
            for array, column in zip(out, self.columns[k]):
                array[:, rows] = column[below] + weight * (column[below + 1] - column[below])
        return out


class LayoutEvaluator:
    """Layouts of transducers judged over a work area's points (module docstring).

    Parameters
    ----------
    points : ndarray, shape (M, 3)
        The work area's points, NED [m].
    levels : Levels
        The error levels.
    detection : Detection, optional
        The site's detection (None: every packet heard, as with the paper's fixed channel, whose losses do not
        depend on where the vehicle is; ``loss`` then gives each packet's probability for the availability).
    loss : float
        The probability that a packet is lost where the site does not decide it [0–1].
    compiled : bool
        Run the layout function compiled where a compiler is found (False: casadi's evaluation, the same numbers).
    echo_margin_pct : float
        The prescription's margin from the echo limit [%] (``prescription.echo_margin_pct``: ``echo`` judged by
        :func:`~sblsim.models.design.criteria.judged_echo`).
    """

    def __init__(self, points: np.ndarray, levels: Levels, detection: Detection | None = None, loss: float = 0.0,
                 compiled: bool = True, echo_margin_pct: float = 0.0) -> None:
        self.points = np.ascontiguousarray(points, dtype=float)
        self.levels, self.detection, self.loss, self.compiled = levels, detection, float(loss), compiled
        self.echo_margin_pct = float(echo_margin_pct)
        self.m = self.points.shape[0]
        chunks = -(-self.m // LAYOUT_CHUNK)
        self._padded_points = np.concatenate([self.points, np.repeat(self.points[-1:], chunks * LAYOUT_CHUNK - self.m,
                                                                     axis=0)])
        self.evaluations = 0
        self.counted: Callable[[int], object] | None = None  # told the layouts of each evaluation (the progress)

    def heard(self, layouts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per layout, point and transducer: the weight of its range, its noise variance [m²], its packet's
        probability of being received and the probability that its range is of reflections, each (S, M, n)."""
        s, n = layouts.shape[0], layouts.shape[1]
        shape = (s, self.m, n)
        variance, own = self.levels.noise(self.points, layouts)
        if self.detection is None:
            return (np.ones(shape), np.broadcast_to(variance, shape).copy(),
                    np.full(shape, 1.0 - self.loss), np.zeros(shape))
        probability, scale, echo = self.detection(self.points, layouts)
        if not self.detection.snr:
            return np.ones(shape), np.broadcast_to(variance, shape).copy(), probability, echo
        noise = grown_noise(variance, own, probability, scale)
        return probability, noise, probability, echo

    def evaluate(self, layouts: np.ndarray, arms: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """The accuracy of S layouts at every point.

        Parameters
        ----------
        layouts : ndarray, shape (S, n, 3)
            The transducers' positions, NED [m].
        arms : ndarray, shape (S, n, 3), optional
            Their lever arms in NED [m] (default the positions: a fixed array, or a platform at the origin).

        Returns
        -------
        dict
            ``drms``, ``drms_3d`` [m], ``log_det``, ``availability`` and ``echo`` [0–1] (as
            :func:`~sblsim.orchestrator.maps.point_accuracy` gives them; ``echo`` on the scale of the echo limit
            with the margin, :func:`~sblsim.models.design.criteria.judged_echo`), each (S, M); the accuracies NaN
            where the probability of a fix is below the map's :data:`~sblsim.orchestrator.maps.MIN_AVAILABILITY`
            (with the site's detection).
        """
        layouts = np.asarray(layouts, dtype=float)
        arms = layouts if arms is None else np.asarray(arms, dtype=float)
        s, n = layouts.shape[:2]
        weight, noise, received, echo = self.heard(layouts)
        out = {name: np.empty((s, self.m)) for name in OUTPUTS}
        function = compiled_layout(slots_for(n)) if self.compiled else None
        for k in range(s):
            if function is None:
                values = layout_values(self.points, layouts[k], arms[k], weight[k], noise[k],
                                       self.levels.attitude_variance, self.levels.depth_variance)
            else:
                values = self._compiled(function, layouts[k], arms[k], weight[k], noise[k])
            for name in OUTPUTS:
                out[name][k] = values[name]
        self.evaluations += s
        if self.counted is not None:
            self.counted(s)
        out["availability"] = fix_probability(received.reshape(s * self.m, n),
                                              self.levels.fix_packets).reshape(s, self.m)
        out["echo"] = judged_echo(1.0 - np.prod(1.0 - received * echo, axis=-1), self.echo_margin_pct)
        if self.detection is not None and self.detection.snr:
            blank = out["availability"] < MIN_AVAILABILITY
            for name in OUTPUTS:
                out[name] = np.where(blank, np.nan, out[name])
        return out

    def _compiled(self, function, layout, arms, weight, noise) -> dict[str, np.ndarray]:
        slots = slots_for(layout.shape[0])
        b, a, w, v = padded(layout, arms, weight, noise, slots)
        total = self._padded_points.shape[0]
        w = np.concatenate([w, np.repeat(w[-1:], total - self.m, axis=0)])
        v = np.concatenate([v, np.repeat(v[-1:], total - self.m, axis=0)])
        b, a = np.ascontiguousarray(b), np.ascontiguousarray(a)
        shared = (np.array([self.levels.attitude_variance]), np.array([self.levels.depth_variance]))
        J = np.empty((total, 9))
        values = [np.empty(total) for _ in OUTPUTS]
        for start in range(0, total, LAYOUT_CHUNK):
            rows = slice(start, start + LAYOUT_CHUNK)
            function([np.ascontiguousarray(self._padded_points[rows]), b, a, np.ascontiguousarray(w[rows]),
                      np.ascontiguousarray(v[rows]), *shared], [J[rows], *(x[rows] for x in values)])
        return {name: x[:self.m] for name, x in zip(OUTPUTS, values)}


__all__ = ["Detection", "LayoutEvaluator", "Levels", "NO_DEPTH_SIGMA", "TABLE_STEP", "judged", "problem_items"]
