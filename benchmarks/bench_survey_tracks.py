"""The moving tags' tracks of a study whose receivers' positions are off, against their truth: their NEES with the
survey error the synchronisation sees taken in every σ (the default where none is stated), and with the positions
taken as exact (``survey_sigma=0``, the default before).

Run:  python benchmarks/bench_survey_tracks.py [--seeds 20] [--sigma 2] [--receivers 9,16] [--tags 4] [--hours 6]

Each seed simulates a study (:func:`sblsim.orchestrator.telemetry.simulate.simulate_study`: ``--receivers`` receivers
each with its sync tag, ``--tags`` animal tags, ``--hours`` hours, 0.15 ms of timing noise), moves every deployment
by N(0, σ²) per horizontal axis (``--sigma``; the array's truth stays where it was) and runs the study twice on the
moved positions (:func:`~sblsim.orchestrator.telemetry.study.run_study`, one process). Each track's rows are scored
against the tag's true path on the reference receiver's clock: the 2-D NEES of the error on the row's ``sigma_x``,
``sigma_y`` (a consistent σ: 2), the RMS error and the RMS of the 2-D σ. Prints each array's line, then for each
array size the mean NEES over every row of every seed (the guide's consistency: [1.5, 4.5] over 20 seeds) and the
spread of the arrays' own means, then a JSON line.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np


def _scored(study, sim) -> dict:
    """A study's tracked rows against the simulation's truth: NEES, errors and σ, and the survey error it took."""
    reference = study.summary["clocks"]["reference_receiver"]
    names = study.deployments.table["receiver"].astype(str).tolist()
    k = names.index(reference)  # the deployments in the simulation's order (none redeployed)
    nees, error, sigma = [], [], []
    for tag in study.tags.itertuples():
        if tag.status != "tracked":
            continue
        mine = study.tracks[study.tracks["tag"] == tag.tag]
        ex, ey = (mine[["x", "y"]].to_numpy() - sim.truth_at(tag.tag, mine["epoch_s"], k)).T
        sx, sy = mine["sigma_x"].to_numpy(), mine["sigma_y"].to_numpy()
        nees.append((ex / sx) ** 2 + (ey / sy) ** 2)
        error.append(np.hypot(ex, ey))
        sigma.append(np.hypot(sx, sy))
    n, e, s = (np.concatenate(v) for v in (nees, error, sigma))
    clocks = study.summary["clocks"]
    return {"nees": n, "rms_m": float(np.sqrt(np.mean(e ** 2))), "sigma_rms_m": float(np.sqrt(np.mean(s ** 2))),
            "survey_sigma_m": clocks.get("survey_sigma_m"), "from": clocks.get("survey_sigma_from")}


def array(seed: int, sigma: float, receivers: int, tags: int, hours: float, folder: Path) -> dict:
    """One study on positions off by ``sigma`` [m per axis], tracked with the error seen taken and as exact."""
    from sblsim.orchestrator.telemetry.simulate import simulate_study
    from sblsim.orchestrator.telemetry.study import run_study

    sim = simulate_study(n_receivers=receivers, n_tags=tags, days=hours / 24.0, redeployed=0, seed=seed)
    files = sim.write(folder / "in", "vue")
    off = sim.positions[:, :2] + sigma * np.random.default_rng(100 + seed).normal(size=(len(sim.positions), 2))
    lat, lon = sim.frame.to_latlon(off[:, 0], off[:, 1])
    sim.deployments.assign(deploy_lat=lat, deploy_long=lon).to_csv(files["deployments"], index=False,
                                                                   float_format="%.10f")
    animals = [t for t in sim.sheet["transmitter"] if t not in set(sim.deployments["transmitter"])]
    found = {}
    for label, survey in (("taken", None), ("exact", 0.0)):
        study = run_study(files["detections"], files["deployments"], files["tags"], workdir=folder / label,
                          chosen=animals, workers=1, survey_sigma=survey)
        found[label] = _scored(study, sim)
    return found


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--sigma", type=float, default=2.0)
    parser.add_argument("--receivers", default="9,16")
    parser.add_argument("--tags", type=int, default=4)
    parser.add_argument("--hours", type=float, default=6.0)
    args = parser.parse_args(argv)
    result = {"sigma_m": args.sigma, "seeds": args.seeds, "tags": args.tags, "hours": args.hours, "arrays": []}
    print("receivers seed  survey σ taken [m]  NEES taken  NEES exact  RMS error [m]  σ RMS taken, exact [m]")
    for receivers in (int(r) for r in args.receivers.split(",")):
        rows = []
        for seed in range(1, args.seeds + 1):
            with tempfile.TemporaryDirectory(prefix="sblsim-survey-tracks-") as tmp:
                found = array(seed, args.sigma, receivers, args.tags, args.hours, Path(tmp))
            taken, exact = found["taken"], found["exact"]
            seen = "none" if taken["survey_sigma_m"] is None else f"{taken['survey_sigma_m']:.2f}"
            print(f"{receivers:9d} {seed:4d}  {seen:>18}  {np.mean(taken['nees']):10.2f}  "
                  f"{np.mean(exact['nees']):10.2f}  {taken['rms_m']:13.2f}  {taken['sigma_rms_m']:.2f}, "
                  f"{exact['sigma_rms_m']:.2f}", flush=True)
            rows.append(found)
        pooled = {label: float(np.mean(np.concatenate([r[label]["nees"] for r in rows])))
                  for label in ("taken", "exact")}
        means = {label: [float(np.mean(r[label]["nees"])) for r in rows] for label in ("taken", "exact")}
        print(f"{receivers} receivers, {args.seeds} arrays: NEES over every row {pooled['taken']:.2f} with the "
              f"survey error seen taken (arrays' means {min(means['taken']):.2f} to {max(means['taken']):.2f}), "
              f"{pooled['exact']:.2f} with the positions taken as exact ({min(means['exact']):.2f} to "
              f"{max(means['exact']):.2f}); 2 when consistent", flush=True)
        result["arrays"].append({"receivers": receivers, "nees_taken": pooled["taken"], "nees_exact": pooled["exact"],
                                 "array_means": means,
                                 "seen_m": [r["taken"]["survey_sigma_m"] for r in rows],
                                 "rms_m": [r["taken"]["rms_m"] for r in rows]})
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
