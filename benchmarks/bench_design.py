"""Time the design's evaluation of a layout and the worked design, against the map's function in the same run.

Run:  python benchmarks/bench_design.py [--repeats N] [--workers N] [--skip-design]

1. **One candidate over 441 points**: an LBL layout of 3 to 8 transponders at the ``lbl-field`` site (detection by
   signal-to-noise, its eigenrays) over a 441-point work area (a 2 km square, 21 × 21 points, the vehicle at
   150 m), evaluated as the design's search evaluates it (the compiled layout function, the site's detection
   tabulated: :class:`sblsim.orchestrator.design.evaluate.LayoutEvaluator`), best of ``--repeats`` rounds of 50
   layouts on one core, against the same layouts through ``sblsim map``'s function one by one
   (:func:`sblsim.orchestrator.maps.point_accuracy` of each layout's plan: the eigenrays of every pair solved, the
   information by casadi's evaluation), timed on a few of them; both give the same DRMS where every packet is heard
   (checked, 1e-3). Target: ≤ 1 ms per layout.
2. **The worked design** (``sblsim design lbl-field-2km``: LBL of 3 to 8 transponders placed freely, two ranging
   grades, SBL and USBL with their grades, each proposal confirmed by Monte Carlo) with ``--workers`` processes:
   its wall time, the layouts it evaluated, and what evaluating those layouts one by one through the map's
   function would take (the count times the time per layout measured in 1).
   Target: ≤ 2 minutes on 2 cores, its Monte Carlo included.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def layouts(count: int, n: int, seed: int = 0) -> np.ndarray:
    """``count`` random layouts of n transponders on the lbl-field floor within 2.5 km, (count, n, 3) NED [m]."""
    rng = np.random.default_rng(seed)
    radius, angle = 2500.0 * np.sqrt(rng.uniform(0, 1, (count, n))), rng.uniform(0, 2 * np.pi, (count, n))
    return np.stack([radius * np.cos(angle), radius * np.sin(angle), np.full((count, n), 299.0)], axis=-1)


def candidate_times(n: int, repeats: int, map_samples: int = 3) -> dict:
    """Per-layout times [s] of the search's evaluation and of the map's function, and their largest DRMS difference."""
    from sblsim.models.table_text import format_table
    from sblsim.orchestrator.cosim.plan import load_plan
    from sblsim.orchestrator.design.area import Area, work_area_points
    from sblsim.orchestrator.design.evaluate import Detection, LayoutEvaluator, Levels
    from sblsim.orchestrator.maps import point_accuracy

    points = work_area_points(Area(vertices=np.array([[-1000.0, -1000.0], [-1000.0, 1000.0], [1000.0, 1000.0],
                                                      [1000.0, -1000.0]])), 21, [150.0])
    assert len(points) == 441
    batch = layouts(50, n)

    def plan_of(layout):
        return load_plan("lbl-field", ["platform.layout=custom", f"platform.beacons={n}",
                                       f"platform.beacon_offsets={format_table(layout)}"])

    plan = plan_of(batch[0])
    evaluator = LayoutEvaluator(points, Levels.of(plan), Detection(plan, 299.0, [150.0], 6000.0))
    fast = evaluator.evaluate(batch)  # the compiled library loaded once
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fast = evaluator.evaluate(batch)
        best = min(best, (time.perf_counter() - start) / len(batch))
    slow, difference = np.inf, 0.0
    for layout, row in zip(batch[:map_samples], fast["drms"]):
        start = time.perf_counter()
        values = point_accuracy(plan_of(layout), points)
        slow = min(slow, time.perf_counter() - start)
        heard = values["availability"] > 0.999
        difference = max(difference, float(np.max(np.abs(values["drms"][heard] / row[heard] - 1.0))))
    return {"search": best, "map": slow, "difference": difference}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="timed rounds of 50 layouts (the best is kept)")
    parser.add_argument("--workers", type=int, default=2, help="processes of the worked design (default 2)")
    parser.add_argument("--skip-design", action="store_true", help="time the candidates only")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats: must be at least 1")
    if args.workers < 1:
        parser.error("--workers: must be at least 1")
    print("1. one LBL layout over a 441-point work area at lbl-field (the search's evaluation; the map's function)")
    per_layout = {}
    for n in (3, 4, 6, 8):
        t = candidate_times(n, args.repeats)
        per_layout[n] = t["map"]
        print(f"   {n} transponders: {1e3 * t['search']:.3f} ms per layout (target <= 1 ms); the map's function "
              f"{t['map']:.2f} s; ratio {t['map'] / t['search']:.0f}x; largest DRMS difference {t['difference']:.1e}")
    if args.skip_design:
        return
    import sblsim

    start = time.perf_counter()
    result = sblsim.design("lbl-field-2km", workers=args.workers)
    total = time.perf_counter() - start
    search = result.document["search"]
    print(f"2. sblsim design lbl-field-2km --workers {args.workers}: {total:.1f} s in all, its Monte Carlo included "
          f"(target <= 120 s on 2 cores); {search['candidates']} candidates, {search['layouts']:,} layouts evaluated "
          f"over {search['work_area_points']} points")
    print(f"   {result.summary}")
    one_by_one = search["layouts"] * per_layout[4]
    print(f"   the same layouts one by one through the map's function: about {one_by_one:,.0f} s (at its "
          f"{per_layout[4]:.2f} s per 4-transponder layout over 441 points)")


if __name__ == "__main__":
    main()
