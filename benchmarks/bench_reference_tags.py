"""Reference tags at their receivers in a study whose receivers' positions are off: the NEES the study scores them
with, against the NEES of their places against the truth and of the score without the cross term.

Run:  python benchmarks/bench_reference_tags.py [--seeds 24] [--sigma 2] [--receivers 9,16] [--hours 6]

Each seed simulates a study (:func:`sblsim.orchestrator.telemetry.simulate.simulate_study`: ``--receivers``
receivers each with its sync tag, no animals, ``--hours`` hours), gives three of its sync tags, drawn from the seed,
as reference tags at their receivers (the tag sheet's role ``reference`` and ``receiver``; their deployments'
sync-tag cells emptied, so the other sync tags synchronise), moves every deployment by N(0, σ²) per horizontal axis
(``--sigma``; the tags stay at the receivers' true positions) and runs the study
(:func:`~sblsim.orchestrator.telemetry.study.run_study`, one process) twice: the survey error stated as σ, and
seen (the synchronisation's, the default where none is stated). Each reference tag is scored three ways, each a 2-D
NEES (a consistent σ: 2):

* **scored**: the study's own (``reference_tags.csv``), the place against its receiver's surveyed position on
  ``P + Q − X − Xᵀ`` (``P`` the place's covariance, ``Q`` the survey's, ``X`` the place's covariance with its own
  receiver's survey error: :mod:`sblsim.orchestrator.telemetry.reference_tags`);
* **no cross**: the same error on ``P + Q`` (the place and the position taken as independent);
* **truth**: the place against the tag's true position on ``P`` alone (what the survey's error did to the place is
  in ``P``; the position scored against has none).

Prints each study's line, then for each array size and survey error the mean of each over every tag of every seed,
beside the interval in which the mean of that many consistent tags' NEES lies in 90 % of studies, then a JSON line.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

#: The reference tags of each study.
REFERENCES = 3


def _scored(folder: Path, truth: dict[str, np.ndarray]) -> list[dict]:
    """Each reference tag of a written study (``folder``) scored three ways (the module docstring)."""
    import pandas as pd

    tags = pd.read_csv(folder / "tags.csv", dtype={"tag": str}).set_index("tag")
    tracks = pd.read_csv(folder / "tracks.csv", dtype={"tag": str})
    scored = pd.read_csv(folder / "reference_tags.csv", dtype={"tag": str}).set_index("tag")
    rows = []
    for tag, true in truth.items():
        if tag not in scored.index or not np.isfinite(scored.loc[tag, "nees"]):
            rows.append({"tag": tag, "scored": float("nan"), "no_cross": float("nan"), "truth": float("nan")})
            continue
        still = json.loads((folder / tags.loc[tag, "folder"] / "summary.json").read_text())["motion"]["still"]
        P = np.asarray(still["covariance"], float)[:2, :2]
        place = tracks.loc[tracks["tag"] == tag, ["x", "y"]].to_numpy(float)[0]  # a still tag: one place
        surveyed = scored.loc[tag, ["truth_x_m", "truth_y_m"]].to_numpy(float)
        survey = scored.loc[tag, "survey_sigma_m"]
        Q = (0.0 if not np.isfinite(survey) else survey**2) * np.eye(2)
        e, t = place - surveyed, place - true
        rows.append({"tag": tag, "scored": float(scored.loc[tag, "nees"]),
                     "no_cross": float(e @ np.linalg.solve(P + Q, e)), "truth": float(t @ np.linalg.solve(P, t)),
                     "error_m": float(np.hypot(*t))})
    return rows


def study(seed: int, sigma: float, receivers: int, hours: float, folder: Path) -> dict:
    """One study on positions off by ``sigma`` [m per axis], run with that error stated and with the one seen."""
    from sblsim.orchestrator.telemetry.outputs import write_study
    from sblsim.orchestrator.telemetry.simulate import simulate_study
    from sblsim.orchestrator.telemetry.study import run_study

    sim = simulate_study(n_receivers=receivers, n_tags=0, days=hours / 24.0, redeployed=0, seed=seed)
    files = sim.write(folder / "in", "vue")
    off = sim.positions[:, :2] + sigma * np.random.default_rng(100 + seed).normal(size=(len(sim.positions), 2))
    at = np.sort(np.random.default_rng(200 + seed).choice(len(sim.deployments), REFERENCES, replace=False))
    deployments, sheet, references = sim.with_reference_tags(at, off)
    deployments.to_csv(files["deployments"], index=False, float_format="%.10f")
    sheet.to_csv(files["tags"], index=False)
    truth = {tag: sim.positions[k, :2] for tag, k in zip(references, at)}
    found = {}
    for label, survey in (("stated", sigma), ("seen", None)):
        outcome = run_study(files["detections"], files["deployments"], files["tags"], workdir=folder / label,
                            chosen=references, workers=1, survey_sigma=survey)
        write_study(outcome, folder / f"{label}-out")
        found[label] = {"tags": _scored(folder / f"{label}-out", truth),
                        "survey_sigma_m": outcome.summary["clocks"].get("survey_sigma_m")}
    return found


def interval(n: int) -> tuple[float, float]:
    """Where the mean of n consistent 2-D NEES lies in 90 % of studies: χ²(2n)/n's 5 % and 95 % quantiles."""
    from scipy.stats import chi2

    return float(chi2.ppf(0.05, 2 * n) / n), float(chi2.ppf(0.95, 2 * n) / n)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=24)
    parser.add_argument("--sigma", type=float, default=2.0)
    parser.add_argument("--receivers", default="9,16")
    parser.add_argument("--hours", type=float, default=6.0)
    args = parser.parse_args(argv)
    result = {"sigma_m": args.sigma, "seeds": args.seeds, "hours": args.hours, "arrays": []}
    print("receivers seed  survey σ seen [m]  NEES stated: scored, no cross, truth   seen: scored, no cross, truth")
    for receivers in (int(r) for r in args.receivers.split(",")):
        runs = []
        for seed in range(1, args.seeds + 1):
            with tempfile.TemporaryDirectory(prefix="sblsim-reference-tags-") as tmp:
                found = study(seed, args.sigma, receivers, args.hours, Path(tmp))
            means = {label: [np.nanmean([r[k] for r in found[label]["tags"]]) for k in ("scored", "no_cross", "truth")]
                     for label in ("stated", "seen")}
            seen = found["seen"]["survey_sigma_m"]
            print(f"{receivers:9d} {seed:4d}  {'none' if seen is None else f'{seen:.2f}':>17}  "
                  + "            ".join(", ".join(f"{v:.2f}" for v in means[label]) for label in ("stated", "seen")),
                  flush=True)
            runs.append(found)
        entry = {"receivers": receivers}
        for label in ("stated", "seen"):
            rows = [r for run in runs for r in run[label]["tags"]]
            pooled = {k: float(np.nanmean([r[k] for r in rows])) for k in ("scored", "no_cross", "truth")}
            n = int(np.sum(np.isfinite([r["scored"] for r in rows])))
            low, high = interval(n)
            print(f"{receivers} receivers, the survey error {label}: {n} reference tags of {len(rows)} scored, NEES "
                  f"{pooled['scored']:.2f} as scored, {pooled['no_cross']:.2f} without the cross term, "
                  f"{pooled['truth']:.2f} against the truth ({low:.2f} to {high:.2f} in 90 % of consistent studies)",
                  flush=True)
            entry[label] = {**pooled, "tags": n, "of": len(rows), "interval": [low, high],
                            "median_error_m": float(np.nanmedian([r.get("error_m", np.nan) for r in rows]))}
        entry["seen_m"] = [run["seen"]["survey_sigma_m"] for run in runs]
        result["arrays"].append(entry)
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
