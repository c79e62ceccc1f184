"""Still tags: the verdict "moved beyond what its error terms allow" and the σ of its place, on simulated records.

Run:  python benchmarks/bench_still_tags.py [--seeds N] [--interval LO HI] [--pings N] [--receivers K]
                                             [--reflection SHARE] [--site open|canal]

A tag at a fixed place among 8 receivers (1 km × 0.8 km), a ping every 120 ± 24 s over a day, each receiver hearing
80 % with 0.1 ms noise, in water whose sound speed is 1,480 ± 5 m/s over the day (a sine of random phase), tracked as
``sblsim replay --motion stationary`` does (``sblsim.orchestrator.tracks.track.track``, the sound speed calibrated from
the pings): for ``--seeds`` still tags, the share of rows flagged and the mean 2-D NEES of the place against the
truth with the covariance reported; the same tags' fixes under the permutation test of their order alone (the verdict
before: :func:`sblsim.models.tracking.stationary.moved`); a tag moved 20 m at its 360th ping, where its rows are
flagged ``tag_moved`` from (None where none is); one drifting off from its 360th ping at 1, 0.2 and 0.05 m a ping
(:data:`DRIFTS`, a dead fish in a current), the same (and the largest error of a row left ``ok``); a random walk of
2 m per ping (an animal); the share of its
arrivals each one's place explains (``explained_share``: the still tags', the moved tags' two places' and their second
places', the walks'; their least, median and largest); and the verdict's own time on 10⁴ fixes, still and moved
(best of three). Prints a JSON line last.

The record varied the way real still tags' records differ: ``--interval`` the pings' interval [s] (uniform between
the two: a sync tag's 540 660), ``--pings`` their count (a season's), ``--receivers`` the first K receivers alone (4
to 8: an array that lost some), ``--reflection`` the share of the record [0, 1) in which receiver H2 hears a
reflection in place of the direct path (a path longer by 8 to 15 m, in episodes of 2 to 12 hours: a reflection
that comes and goes with the water level), ``--site canal`` another site: K receivers spread evenly along a bent
canal (two legs of 500 m at a right angle, on alternate banks 10 m apart: :func:`canal`), the tag on its second leg
180 m from the bend, moved 20 m along the canal.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

RECEIVERS = np.array([[0.0, 0.0], [1000.0, 0.0], [1000.0, 800.0], [0.0, 800.0], [500.0, 400.0], [250.0, 700.0],
                      [800.0, 150.0], [650.0, 750.0]])
TAG = np.array([780.0, 560.0])
#: The bent canal's tag: on its second leg, 180 m from the bend; moved along the canal.
CANAL_TAG = np.array([503.0, 180.0])
SIGMA = 1e-4
PINGS = 720
#: The drifts' speeds [m a ping] (a dead fish carried off by a current, from the middle ping to the end).
DRIFTS = (1.0, 0.2, 0.05)
SITES = ("open", "canal")


def canal(k: int) -> np.ndarray:
    """K receivers (k, 2) [m] spread evenly along a bent canal: two legs of 500 m at a right angle (east, then north
    from the bend at (500, 0)), on alternate banks 10 m apart."""
    along = np.linspace(0.0, 1000.0, k)
    bank = 5.0 * (-1.0) ** np.arange(k)
    return np.where((along <= 500.0)[:, None], np.column_stack([along, bank]),
                    np.column_stack([500.0 + bank, along - 500.0]))


@dataclass(frozen=True)
class Record:
    """How a simulated record is made (the module docstring): the pings' interval [s], their count, the receivers
    used, the share of the record a reflection replaces H2's direct path, and the site (:data:`SITES`)."""

    interval: tuple[float, float] = (96.0, 144.0)
    pings: int = PINGS
    receivers: int = len(RECEIVERS)
    reflection: float = 0.0
    site: str = "open"

    def layout(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The receivers (K, 2) [m], the tag's place (2,) [m] and the move of a moved tag (2,) [m]."""
        if self.site == "canal":
            return canal(self.receivers), CANAL_TAG, np.array([0.0, 20.0])
        return RECEIVERS[:self.receivers], TAG, np.array([20.0, 0.0])

    def __str__(self) -> str:
        said = f"a ping every {self.interval[0]:g}-{self.interval[1]:g} s, {self.pings} pings"
        said += f", {self.receivers} receivers" + (" along a bent canal" if self.site == "canal" else "")
        return said + (f", a reflection at H2 {100 * self.reflection:g} % of the time" if self.reflection else "")


def _reflected(rng: np.random.Generator, t: np.ndarray, share: float) -> tuple[np.ndarray, np.ndarray]:
    """Which of the pings at times ``t`` (n,) [s] a reflection replaces, in episodes of 2 to 12 hours covering about
    ``share`` of the record, and its excess path (n,) [m] (8 to 15 m, one per episode)."""
    on = np.zeros(len(t), bool)
    excess = np.zeros(len(t))
    if share <= 0:
        return on, excess
    span = t[-1] - t[0]
    covered = 0.0
    while covered < share * span:
        length = rng.uniform(2.0, 12.0) * 3600.0
        start = rng.uniform(t[0] - length, t[-1])
        here = (t >= start) & (t < start + length) & ~on
        on |= here
        excess[here] = rng.uniform(8.0, 15.0)
        covered += length
    return on, excess


def record(folder: Path, seed: int, move: np.ndarray | None = None, walk: float | None = None,
           how: Record = Record(), drift: float | None = None):
    """A simulated record's TOA and receivers files in ``folder``, and the tag's place at each ping (module
    docstring)."""
    from sblsim.orchestrator.tracks.variants import write_toa

    rng = np.random.default_rng(seed)
    n = how.pings
    receivers, tag, _ = how.layout()
    t = _emissions(rng, how)
    c = 1480.0 + 5.0 * np.sin(2 * np.pi * t / 86400.0 + rng.uniform(0, 2 * np.pi))
    places = np.repeat(tag[None], n, axis=0)
    if move is not None:
        places[n // 2:] += move
    if walk is not None:
        places = places + np.cumsum(rng.normal(scale=walk, size=(n, 2)), axis=0)
    if drift is not None:  # along the move's direction, the middle ping the first moved
        way = how.layout()[2] / np.linalg.norm(how.layout()[2])
        places[n // 2:] += drift * np.arange(1, n - n // 2 + 1)[:, None] * way
    path = np.linalg.norm(places[:, None] - receivers[None], axis=2)
    on, excess = _reflected(np.random.default_rng([seed, 1]), t, how.reflection)  # (its own draws: the rest alike)
    path[:, 1] += np.where(on, excess, 0.0)
    toa = t[:, None] + path / c[:, None]
    toa = toa + SIGMA * rng.normal(size=toa.shape)
    toa[rng.random(toa.shape) > 0.8] = np.nan
    names = [f"H{k + 1}" for k in range(len(receivers))]
    write_toa(folder / "toa.txt", toa, names)
    rows = "\n".join(f"{name},{x:g},{y:g}" for name, (x, y) in zip(names, receivers))
    (folder / "receivers.csv").write_text("name,x_m,y_m\n" + rows + "\n")
    return folder / "toa.txt", folder / "receivers.csv", places


def _emissions(rng: np.random.Generator, how: Record) -> np.ndarray:
    """A record's emission times (pings,) [s]: its intervals drawn uniform in ``how.interval``, the first draws of
    its seed's generator."""
    return np.cumsum(rng.uniform(*how.interval, how.pings))


def pings(outcome, seed: int, how: Record = Record()) -> np.ndarray:
    """Each row of a tracked record's track: its ping (the record's emission nearest the row's time; a ping heard by
    too few receivers has no row)."""
    t = _emissions(np.random.default_rng(seed), how)  # the record's first draws
    time = outcome.track["time"].to_numpy(float)
    after = np.clip(np.searchsorted(t, time), 1, len(t) - 1)
    return np.where(np.abs(t[after] - time) < np.abs(t[after - 1] - time), after, after - 1)


def first_flagged(outcome, seed: int, how: Record = Record()) -> int | None:
    """The first ping flagged ``tag_moved`` from the middle ping [pings] (None where none is)."""
    reasons = outcome.track["quality_reason"].str.contains("tag_moved").to_numpy()
    return int(pings(outcome, seed, how)[np.argmax(reasons)]) - how.pings // 2 if reasons.any() else None


def tracked(folder: Path, seed: int, **kw):
    """The record tracked as a still tag: the outcome, the places, and the seconds it took."""
    from sblsim.orchestrator.tracks.track import track

    toa, receivers, places = record(folder, seed, **kw)
    start = time.perf_counter()
    outcome = track(toa, receivers, motion="stationary", toa_sigma=SIGMA, other_filters=False)
    return outcome, places, time.perf_counter() - start


def verdict_time(moved_by: float) -> float:
    """The best of three times [s] of :func:`~sblsim.models.tracking.still.still_verdict` on 10⁴ fixes (a ping a
    minute, 0.2 m noise, a slow error of 1 m), moved by ``moved_by`` [m] half way."""
    from sblsim.models.tracking.still import still_verdict

    rng = np.random.default_rng(0)
    n = 10_000
    x = rng.normal(scale=0.2, size=(n, 2))
    x[n // 2:, 0] += moved_by
    R = np.tile(0.04 * np.eye(2), (n, 1, 1))
    best = np.inf
    for _ in range(3):
        start = time.perf_counter()
        still_verdict(x, R, np.arange(n) * 60.0, np.ones(n, bool), np.eye(2))
        best = min(best, time.perf_counter() - start)
    return best


def measure(seeds: int, how: Record = Record()) -> dict:
    """The figures (module docstring) on records made as ``how`` says."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        nees, flagged, rows, order_moved, seconds = [], 0, 0, 0, []
        shares = {"still": [], "moved": [], "second": [], "walk": []}
        for seed in range(seeds):
            outcome, places, took = tracked(folder, seed, how=how)
            still = outcome.summary["motion"]["still"]
            shares["still"].append(still["explained_share"])
            e = np.asarray(still["place"]) - places[0]
            nees.append(float(e @ np.linalg.solve(np.asarray(still["covariance"]), e)))
            flagged += int((outcome.track["quality"] == "flagged").sum())
            rows += len(outcome.track)
            order_moved += bool(outcome.summary["motion"]["moved_test"]["in_order"])
            seconds.append(took)
        offsets, before_ok, distance = [], [], []
        for seed in range(5):
            outcome, places, _ = tracked(folder, seed, move=how.layout()[2], how=how)
            reasons = outcome.track["quality_reason"].str.contains("tag_moved").to_numpy()
            first = int(np.argmax(reasons)) if reasons.any() else len(reasons)
            offsets.append(first_flagged(outcome, seed, how))
            before_ok.append(bool((outcome.track["quality"].to_numpy()[:first] == "ok").all()))
            change = outcome.summary["motion"]["still"]["change"]  # None: the move not found (NaN)
            shares["moved"].append(outcome.summary["motion"]["still"]["explained_share"])  # its two places'
            second = change.get("second_place_explained_share") if change else None
            shares["second"].append(float("nan") if second is None else second)
            distance.append(float(np.linalg.norm(np.asarray(change["second_place"]) - places[-1])) if change
                            else float("nan"))
        drifts = {}
        for speed in DRIFTS:
            drifts[speed] = {"offsets": [], "ok_error_m": [], "verdicts": []}
            for seed in range(5):
                outcome, places, _ = tracked(folder, seed, drift=speed, how=how)
                drifts[speed]["offsets"].append(first_flagged(outcome, seed, how))
                ok = (outcome.track["quality"] == "ok").to_numpy()
                off = np.hypot(*(outcome.track[["x", "y"]].to_numpy() - places[pings(outcome, seed, how)]).T)
                drifts[speed]["ok_error_m"].append(float(off[ok].max()) if ok.any() else None)
                drifts[speed]["verdicts"].append(outcome.summary["motion"]["still"]["verdict"])
        animals = []
        for seed in range(5):
            still = tracked(folder, seed, walk=2.0, how=how)[0].summary["motion"]["still"]
            animals.append(still["verdict"])
            shares["walk"].append(still["explained_share"])
    return {"record": str(how), "seeds": seeds, "rows": rows, "flagged": flagged, "share_flagged": flagged / rows,
            "nees_mean": float(np.mean(nees)), "nees_median": float(np.median(nees)),
            "order_test_moved": order_moved, "track_s_median": float(np.median(seconds)),
            "moved_first_flag_offsets": offsets, "moved_rows_before_ok": before_ok,
            "moved_second_place_error_m": distance, "drifts": drifts, "animal_verdicts": animals,
            "explained_share": {kind: [float(np.nanmin(v)), float(np.nanmedian(v)), float(np.nanmax(v))]
                                for kind, v in shares.items() if np.isfinite(v).any()},
            "verdict_1e4_still_s": verdict_time(0.0), "verdict_1e4_moved_s": verdict_time(20.0)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20, help="still tags simulated")
    parser.add_argument("--interval", type=float, nargs=2, default=Record.interval, metavar=("LO", "HI"),
                        help="the pings' interval [s], uniform between the two (default 96 144)")
    parser.add_argument("--pings", type=int, default=PINGS, help=f"pings a record (default {PINGS})")
    parser.add_argument("--receivers", type=int, default=len(RECEIVERS),
                        help=f"the first K receivers alone (4 to {len(RECEIVERS)})")
    parser.add_argument("--site", choices=SITES, default="open",
                        help="open: 8 receivers over 1 km x 0.8 km; canal: K receivers along a bent canal")
    parser.add_argument("--reflection", type=float, default=0.0,
                        help="the share of the record a reflection replaces H2's direct path [0, 1)")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error("--seeds: must be at least 1")
    if not 0 < args.interval[0] <= args.interval[1]:
        parser.error(f"--interval: {args.interval[0]:g} {args.interval[1]:g}; allowed: 0 < LO <= HI [s]")
    if args.pings < 40:
        parser.error(f"--pings: {args.pings}; allowed: 40 or more")
    if not 4 <= args.receivers <= len(RECEIVERS):
        parser.error(f"--receivers: {args.receivers}; allowed: 4 to {len(RECEIVERS)}")
    if not 0 <= args.reflection < 1:
        parser.error(f"--reflection: {args.reflection:g}; allowed: 0 <= SHARE < 1")
    how = Record(tuple(args.interval), args.pings, args.receivers, args.reflection, args.site)
    r = measure(args.seeds, how)
    print(f"records: {how}")
    print(f"{r['seeds']} still tags in water of 1480 ± 5 m/s (a sine of a day): {r['flagged']} of {r['rows']} rows "
          f"flagged ({100 * r['share_flagged']:.1f} %), mean 2-D NEES {r['nees_mean']:.2f} "
          f"(median {r['nees_median']:.2f}); "
          f"the permutation test of their fixes' order alone says {r['order_test_moved']} of {r['seeds']} moved; "
          f"a still tag tracked in {r['track_s_median']:.2f} s (median)")
    second = np.round(r["moved_second_place_error_m"], 2).tolist()
    print(f"moved 20 m at ping {how.pings // 2}: first flagged row {r['moved_first_flag_offsets']} pings from the move,"
          " "
          f"the rows before ok {r['moved_rows_before_ok']}, the second place {second} m from where it went; a random "
          f"walk of 2 m per ping: {r['animal_verdicts']}")
    for speed, d in r["drifts"].items():
        largest = [None if e is None else round(e, 2) for e in d["ok_error_m"]]
        print(f"drifting off at {speed:g} m per ping from ping {how.pings // 2}: first flagged row {d['offsets']} "
              f"pings from the onset, the largest error of a row ok {largest} m; {d['verdicts']}")
    said = "; ".join(f"{kind} {low:.3f} to {high:.3f} (median {mid:.3f})"
                     for kind, (low, mid, high) in r["explained_share"].items())
    print(f"the share of its arrivals each place explains (the moved tags' two places', their second places'): "
          f"{said}")
    print(f"the verdict on 10^4 fixes: {r['verdict_1e4_still_s']:.3f} s still, {r['verdict_1e4_moved_s']:.3f} s moved "
          "(best of three)")
    print(json.dumps(r))


if __name__ == "__main__":
    main()
