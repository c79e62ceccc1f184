"""A study's tracks on receivers' positions refined from its own pings (``--refine-positions``), against their truth:
the RMS error and the NEES, beside the same study on the true positions.

Run:  python benchmarks/bench_refined_tracks.py [--cases 16:3:4,9:9:5,...] [--from-sync]

Each case ``RECEIVERS:SYNC_TAGS:SEED`` simulates a study (:func:`sblsim.orchestrator.telemetry.simulate.simulate_study`:
the receivers on a grid, 2 animals, 6 hours, 0.15 ms of timing noise), keeps the sync tags of SYNC_TAGS receivers
drawn from ``100 + SEED`` (the others listen only), moves every deployment by 1 to 5 m in a random direction drawn
from ``1000 + SEED``, the moves' translation, rotation and dilation taken out (what no time of arrival sees where the
sound speed is calibrated: the survey's), and runs :func:`sblsim.track` (2 worker processes) on the true positions
and, with ``refine_positions``, on the moved ones. Each track's rows not flagged are scored against the animal's true
path on the reference receiver's clock: the 2-D RMS error and the mean 2-D NEES on the rows' ``sigma_x``,
``sigma_y`` (2 when consistent). Prints a line per case, then a JSON line.

With ``--from-sync`` the positions are refined by the synchronisation instead (:func:`sblsim.sync` with
``refine_positions``, from the sync tags alone, the sound speed fitted with them), and the study is given its folder
(``sync``) twice: taking each receiver's position error from it (``positions.csv``'s ``position_sigma_m``) and with
the positions taken as exact (``survey_sigma=0``: the code before carried none); the default cases are then
:data:`SYNC_CASES`.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

#: The cases of the docs' table: receivers, sync tags, seed.
CASES = "16:3:4,16:3:6,16:3:7,16:3:11,12:2:8,20:4:9,9:3:10,16:16:4,9:9:5"
#: The cases of the docs' table of the synchronisation's refined positions given to a study (``--from-sync``).
SYNC_CASES = "12:5:4,16:6:4,16:8:5,9:9:4"


def _shape_only(errors: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Position errors (R, 2) [m] less their best translation, rotation and dilation about ``at``'s centroid (least
    squares)."""
    centred = at - at.mean(axis=0)
    design = np.zeros((2 * len(at), 4))
    design[0::2, 0] = design[1::2, 1] = 1.0
    design[0::2, 2], design[1::2, 2] = -centred[:, 1], centred[:, 0]
    design[0::2, 3], design[1::2, 3] = centred[:, 0], centred[:, 1]
    v = np.ravel(errors)
    return (v - design @ np.linalg.lstsq(design, v, rcond=None)[0]).reshape(-1, 2)


def _scored(sim, result) -> dict:
    """The rows not flagged against the truth: RMS error [m] and mean 2-D NEES."""
    reference = result.summary["clocks"]["reference_receiver"]
    k = int(np.flatnonzero(result.receivers["receiver"].to_numpy() == reference)[0])
    errors, nees = [], []
    for tag, rows in result.tracks.groupby("tag"):
        ok = (rows["quality"] == "ok").to_numpy()
        ex, ey = (rows[["x", "y"]].to_numpy()[ok] - sim.truth_at(tag, rows["epoch_s"].to_numpy()[ok], k)).T
        errors.append(np.hypot(ex, ey))
        nees.append((ex / rows["sigma_x"].to_numpy()[ok]) ** 2 + (ey / rows["sigma_y"].to_numpy()[ok]) ** 2)
    e, n = np.concatenate(errors), np.concatenate(nees)
    return {"rms_m": float(np.sqrt(np.mean(e ** 2))), "nees": float(np.mean(n)), "rows": int(len(e))}


def case(receivers: int, sync_tags: int, seed: int, folder: Path, from_sync: bool = False) -> dict:
    """One case (the module docstring): the true positions' and the refined study's scores (``from_sync``: the
    studies given the synchronisation's refined positions, with and without their errors)."""
    import sblsim
    from sblsim.orchestrator.telemetry.simulate import simulate_study

    sim = simulate_study(n_receivers=receivers, n_tags=2, days=0.25, redeployed=0, seed=seed)
    if sync_tags < receivers:
        drawn = np.random.default_rng(100 + seed).choice(receivers, size=sync_tags, replace=False)
        keep = {sim.deployments["transmitter"][k] for k in drawn}
        dropped = [t for t in sim.deployments["transmitter"] if t not in keep]
        sim.deployments = sim.deployments.assign(transmitter=[t if t in keep else ""
                                                              for t in sim.deployments["transmitter"]])
        sim.detections = sim.detections[~sim.detections["transmitter"].isin(dropped)].reset_index(drop=True)
    files = sim.write(folder / "in", "vue")
    sheet = pd.read_csv(files["deployments"])
    true = np.c_[sim.frame.from_latlon(sheet["deploy_lat"].to_numpy(), sheet["deploy_long"].to_numpy())]
    rng = np.random.default_rng(1000 + seed)
    direction = rng.normal(size=true.shape)
    moves = rng.uniform(1.0, 5.0, len(true))[:, None] * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    moves = _shape_only(moves, true)
    lat, lon = sim.frame.to_latlon(true[:, 0] + moves[:, 0], true[:, 1] + moves[:, 1])
    moved = folder / "moved.csv"
    sheet.assign(deploy_lat=lat, deploy_long=lon).to_csv(moved, index=False)
    right = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], workers=2)
    if from_sync:
        row = {"receivers": receivers, "sync_tags": sync_tags, "seed": seed, "true": _scored(sim, right)}
        try:
            sblsim.sync(files["detections"], receivers=moved, refine_positions=True, out=folder / "sync")
        except sblsim.SblsimError as exc:  # no receiver determined: said, nothing to track on
            return row | {"refused": str(exc)}
        sigma = pd.read_csv(folder / "sync" / "positions.csv")
        given = {"receivers": moved, "tags": files["tags"], "sync": folder / "sync", "workers": 2}
        return row | {"refined_receivers": int(sigma["refined"].sum()),
                      "position_sigma_m": [float(sigma["position_sigma_m"].min()),
                                           float(sigma["position_sigma_m"].max())],
                      "each": _scored(sim, sblsim.track(files["detections"], **given)),
                      "exact": _scored(sim, sblsim.track(files["detections"], survey_sigma=0, **given))}
    started = time.perf_counter()
    refined = sblsim.track(files["detections"], receivers=moved, tags=files["tags"], workers=2,
                           refine_positions=True)
    return {"receivers": receivers, "sync_tags": sync_tags, "seed": seed, "true": _scored(sim, right),
            "refined": _scored(sim, refined), "kept": bool(refined.summary["positions"]["kept"]),
            "refined_seconds": time.perf_counter() - started}


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default=None, help="RECEIVERS:SYNC_TAGS:SEED, separated by commas")
    parser.add_argument("--from-sync", action="store_true",
                        help="the positions refined by the synchronisation, its folder given to the study")
    args = parser.parse_args(argv)
    rows = []
    print("receivers  sync tags  seed | true positions: RMS [m], NEES | " + (
        "sync's refined positions: receivers refined, position_sigma_m [m] | each one's error: RMS [m], NEES | "
        "taken as exact: RMS [m], NEES" if args.from_sync else "refined: RMS [m], NEES, kept, seconds"))
    for text in (args.cases or (SYNC_CASES if args.from_sync else CASES)).split(","):
        receivers, sync_tags, seed = (int(v) for v in text.split(":"))
        with tempfile.TemporaryDirectory(prefix="sblsim-refined-") as tmp:
            row = case(receivers, sync_tags, seed, Path(tmp), args.from_sync)
        t = row["true"]
        said = f"{receivers:9d}  {sync_tags:9d}  {seed:4d} | {t['rms_m']:.3f}, {t['nees']:.2f} | "
        if "refused" in row:
            said += f"refused: {row['refused']}"
        elif args.from_sync:
            e, x, (low, high) = row["each"], row["exact"], row["position_sigma_m"]
            said += (f"{row['refined_receivers']} of {receivers}, {low:.2f} to {high:.2f} | {e['rms_m']:.3f}, "
                     f"{e['nees']:.2f} | {x['rms_m']:.3f}, {x['nees']:.2f}")
        else:
            r = row["refined"]
            said += f"{r['rms_m']:.3f}, {r['nees']:.2f}, {row['kept']}, {row['refined_seconds']:.0f}"
        print(said, flush=True)
        rows.append(row)
    print(json.dumps(rows))
    return rows


if __name__ == "__main__":
    main()
