"""The survey error a synchronisation's residuals show, against the error put into the receivers' positions.

Run:  python benchmarks/bench_survey_error.py [--seeds N] [--sigmas 0,1,2,3] [--sync-every K] [--receivers R]

Sync tags simulated by :func:`sblsim.models.sync.simulate.simulate_sync` (``--receivers`` receivers in a 1 km square,
their clocks' offsets and drifts, 0.15 ms of timing noise, 6 hours), the sync tags of every ``--sync-every``-th
receiver kept (the others listen only), then synchronised by :func:`sblsim.orchestrator.sync.run.synchronise` on the
positions off by N(0, σ²) per axis for each σ of ``--sigmas``, ``--seeds`` arrays each: the survey error it says
(``summary["survey_error"]``) against σ: the root mean square of σ̂, the share said seen, the mean of its stated
standard error and the spread of σ̂ over the seeds, and the seconds per synchronisation. Prints a table, then a
JSON line.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import pandas as pd


def synchronised(seed: int, sigma: float, receivers: int, every: int) -> tuple[dict, float]:
    """One array's synchronisation on positions off by ``sigma`` [m per axis]: ``survey_error`` and the seconds."""
    from sblsim.models.sync.simulate import simulate_sync
    from sblsim.orchestrator.readers.detections import Detections
    from sblsim.orchestrator.sync.run import synchronise

    sim = simulate_sync(n_receivers=receivers, hours=6.0, seed=seed, noise=0.15e-3, echo_share=0.0)
    own = np.arange(receivers) % every == 0  # the receivers whose sync tag is kept
    keep = own[sim.tag]
    t = sim.time[keep] + 1_700_000_000
    frame = pd.DataFrame({"receiver": [f"R{j}" for j in sim.receiver[keep]],
                          "tag": [f"S{i}" for i in sim.tag[keep]], "time": t, "sensor_value": np.nan,
                          "sensor_unit": "", "line": np.arange(len(t)) + 2})
    xy = sim.positions[:, :2] + sigma * np.random.default_rng(1000 + seed).normal(size=(receivers, 2))
    table = pd.DataFrame({"receiver": [f"R{j}" for j in range(receivers)],
                          "sync_tag": [f"S{j}" if own[j] else "" for j in range(receivers)],
                          "x": xy[:, 0], "y": xy[:, 1], "z": np.nan})
    start = time.perf_counter()
    outcome = synchronise(Detections(frame, "simulated", "yaps"), table, sound_speed=sim.sound_speed, reference="R0")
    return outcome.summary["survey_error"], time.perf_counter() - start


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--sigmas", default="0,1,2,3")
    parser.add_argument("--sync-every", type=int, default=1)
    parser.add_argument("--receivers", type=int, default=12)
    args = parser.parse_args(argv)
    rows = []
    for sigma in (float(s) for s in args.sigmas.split(",")):
        found, seconds = zip(*(synchronised(seed, sigma, args.receivers, args.sync_every)
                               for seed in range(args.seeds)))
        est = np.array([f["survey_sigma_m"] or 0.0 for f in found])
        se = [f["survey_sigma_se_m"] for f in found if f["survey_sigma_se_m"] is not None]
        rows.append({"sigma_m": sigma, "rms_estimate_m": float(np.sqrt(np.mean(est**2))),
                     "seen": float(np.mean([f["seen"] for f in found])),
                     "mean_se_m": float(np.mean(se)) if se else None, "spread_m": float(np.std(est)),
                     "pairs": float(np.mean([f["pairs"] for f in found])),
                     "set_aside": float(np.mean([f["pairs_set_aside"] for f in found])),
                     "seconds": float(np.mean(seconds))})
    print(f"{args.receivers} receivers, a sync tag at every {args.sync_every}, {args.seeds} arrays each")
    print("σ [m]  rms σ̂ [m]  seen  mean se [m]  spread [m]  pairs  set aside  s/sync")
    for r in rows:
        se = "-" if r["mean_se_m"] is None else f"{r['mean_se_m']:.2f}"
        print(f"{r['sigma_m']:5.2f}  {r['rms_estimate_m']:9.3f}  {r['seen']:4.2f}  {se:>11}  {r['spread_m']:10.3f}  "
              f"{r['pairs']:5.0f}  {r['set_aside']:9.1f}  {r['seconds']:6.2f}")
    result = {"receivers": args.receivers, "sync_every": args.sync_every, "seeds": args.seeds, "rows": rows}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
