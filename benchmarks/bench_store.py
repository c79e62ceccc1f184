"""Time reading detections into a store (``sblsim store``) against reading the file whole, for each export, and a
season tracked from its store (the issue "a season, not a week").

Run:  python benchmarks/bench_store.py [--receivers 20] [--tags 100] [--days 7] [--formats vue,fathom,glatos]
      [--season-days 30[,91...]] [--season-tags 40] [--workers 2] [--no-season] [--no-reading]

Reading: the simulated study of ``benchmarks/bench_telemetry_study.py`` (``--days``, ``--tags``) written as each
export; in a fresh process each, the file read whole by the readers (:func:`read_detections`: the baseline, refused
where the file is beyond the whole-file reader's 256 MiB or 3,000,000 rows) and read into a store a piece at a time
(:func:`sblsim.store`): the wall time, the detections per second, the process's peak memory, the store's size, and
the store's time over the whole read's (the ratio).

Season (unless ``--no-season``): ``--season-days`` of ``--season-tags`` tags as a VUE export (a file ``sblsim track``
refuses whole beyond its size); stored, then tracked from the store (:func:`sblsim.track` on the store's folder into
a folder, ``--workers`` processes) in a fresh process: the store's and the track's wall times and peak memory (the
study's own process: its workers hold a tag each), the tags tracked. Several lengths (``--season-days 28,91``): each
in turn, with its time per day and its peak over the first length's (the issue's targets: a season's time linear in
its length, its peak within 20 % whatever the length and at most 4 GiB). A JSON line last.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

from bench_memory import peak_bytes

from sblsim.orchestrator.io.memory import arrow_pool

arrow_pool()  # Arrow's pool as the command line takes it, before pyarrow loads (here and in the worker processes)

import sblsim  # noqa: E402
from sblsim.models.declarations import ModelError  # noqa: E402
from sblsim.orchestrator.readers.detections import read_detections  # noqa: E402
from sblsim.orchestrator.telemetry.simulate import simulate_study  # noqa: E402

#: The issue's targets: detections read into the store per second [1/s], the peak of the reading [GiB].
TARGET_RATE = 1e6
TARGET_PEAK_GIB = 1.0
#: The issue's target for a season's study: its peak [GiB].
TARGET_SEASON_GIB = 4.0


def _peak_gib() -> float:
    """This process's peak resident memory [GiB] (:func:`bench_memory.peak_bytes`: its own high-water mark)."""
    return peak_bytes() / 2**30


def _whole(path: str) -> dict:
    started = time.perf_counter()
    try:
        rows = len(read_detections(path, None).frame)
    except ModelError as exc:
        return {"refused": str(exc)}
    return {"seconds": time.perf_counter() - started, "rows": rows, "peak_gib": _peak_gib()}


def _stored(path: str, out: str) -> dict:
    started = time.perf_counter()
    info = sblsim.store(path, out=out).info
    seconds = time.perf_counter() - started
    size = sum(f.stat().st_size for f in Path(out).rglob("*.parquet"))
    return {"seconds": seconds, "rows": info["rows"], "peak_gib": _peak_gib(), "store_mib": size / 2**20}


def _tracked(store: str, files: dict, out: str, workers: int) -> dict:
    started = time.perf_counter()
    result = sblsim.track(store, receivers=files["deployments"], tags=files["tags"], out=out, workers=workers)
    return {"seconds": time.perf_counter() - started, "peak_gib": _peak_gib(),
            "tracked": int((result.tags["status"] == "tracked").sum()), "tags": int(len(result.tags))}


def _fresh(function, *args) -> dict:
    """``function(*args)`` in a fresh process (its own peak memory)."""
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
        return pool.submit(function, *args).result()


def reading(receivers: int, tags: int, days: float, formats: list[str], folder: Path) -> list[dict]:
    """Each export read whole and into a store (the module docstring)."""
    sim = simulate_study(n_receivers=receivers, n_tags=tags, days=days, seed=1)
    rows = []
    for format in formats:
        files = sim.write(folder / format, format)
        path = str(files["detections"])
        whole = _fresh(_whole, path)
        stored = _fresh(_stored, path, str(folder / f"store_{format}"))
        rate = stored["rows"] / stored["seconds"]
        row = {"format": format, "detections": stored["rows"], "file_mib": Path(path).stat().st_size / 2**20,
               "whole": whole, "store": stored, "rate_per_s": rate,
               "ratio": stored["seconds"] / whole["seconds"] if "seconds" in whole else None}
        rows.append(row)
        said = (f"whole {whole['seconds']:.1f} s, peak {whole['peak_gib']:.2f} GiB" if "seconds" in whole
                else "whole: refused (beyond the file reader's limits)")
        ratio = "-" if row["ratio"] is None else f"{row['ratio']:.2f}"
        print(f"{format:7s} {row['detections']:>10,} detections {row['file_mib']:7.1f} MiB | {said} | store "
              f"{stored['seconds']:.1f} s ({rate:,.0f}/s), peak {stored['peak_gib']:.2f} GiB, "
              f"{stored['store_mib']:.1f} MiB | ratio {ratio}",
              flush=True)
    return rows


def season(receivers: int, tags: int, days: float, workers: int, folder: Path) -> dict:
    """A season stored and tracked from its store (the module docstring)."""
    sim = simulate_study(n_receivers=receivers, n_tags=tags, days=days, seed=1)
    files = sim.write(folder / "season", "vue")
    whole = _fresh(_whole, str(files["detections"]))
    print(f"season: {len(sim.detections):,} detections, {files['detections'].stat().st_size / 2**20:.0f} MiB; "
          f"as a file: {whole.get('refused', 'read')}", flush=True)
    stored = _fresh(_stored, str(files["detections"]), str(folder / "season_store"))
    print(f"season: stored in {stored['seconds']:.1f} s, peak {stored['peak_gib']:.2f} GiB", flush=True)
    tracked = _fresh(_tracked, str(folder / "season_store"), files, str(folder / "season_out"), workers)
    print(f"season: tracked from the store in {tracked['seconds']:.1f} s ({tracked['tracked']} of {tracked['tags']} "
          f"tags), peak {tracked['peak_gib']:.2f} GiB (the main process; each worker holds its tags)", flush=True)
    return {"days": days, "tags": tags, "detections": int(len(sim.detections)), "file_refused": "refused" in whole,
            "store": stored, "track": tracked}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--receivers", type=int, default=20)
    parser.add_argument("--tags", type=int, default=100)
    parser.add_argument("--days", type=float, default=7.0)
    parser.add_argument("--formats", default="vue,fathom,glatos")
    parser.add_argument("--season-days", default="30", help="days, or several separated by commas")
    parser.add_argument("--season-tags", type=int, default=40)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--no-season", action="store_true", help="time the reading only")
    parser.add_argument("--no-reading", action="store_true", help="time the season only")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        rows = [] if args.no_reading else reading(args.receivers, args.tags, args.days, args.formats.split(","),
                                                  folder)
        seasons = [] if args.no_season else [season(args.receivers, args.season_tags, float(d), args.workers,
                                                    folder / f"season_{d}") for d in args.season_days.split(",")]
    if rows:
        print(f"targets: {TARGET_RATE:,.0f} detections/s and {TARGET_PEAK_GIB} GiB reading: " + ", ".join(
            f"{r['format']} {r['rate_per_s']:,.0f}/s {r['store']['peak_gib']:.2f} GiB" for r in rows))
    for row in seasons:  # against the first length, measured in the same run
        first = seasons[0]
        per_day = (row["track"]["seconds"] / row["days"]) / (first["track"]["seconds"] / first["days"])
        print(f"season {row['days']:g} days: {row['track']['seconds'] / row['days']:.1f} s a day "
              f"({per_day:.2f} x the {first['days']:g} days'), peak {row['track']['peak_gib']:.2f} GiB "
              f"({row['track']['peak_gib'] / first['track']['peak_gib']:.2f} x; the targets: within 1.2 x and "
              f"{TARGET_SEASON_GIB:g} GiB)")
    print(json.dumps({"reading": rows, "season": seasons}), file=sys.stdout)


if __name__ == "__main__":
    main()
