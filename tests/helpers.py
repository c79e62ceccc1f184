"""Test helpers: step one model's compiled code directly, as the local engine does; start a child to signal; give
an empty cache the objects the suite compiled; a design problem with some of its keys changed.

``Core(model, params, replicates)`` takes configuration keys (e.g.
``trajectory_file``, ``sound_speed_profile``, ``beacon_offsets``) or FMU
parameters (e.g. ``sample_period``), fills the rest with their declared
starts, and steps a batch of replicates through :class:`sblsim.fmus.native.NativeBatch`.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from sblsim.models.declarations import resolve_parameters
from sblsim.orchestrator.cosim.local_engine import LocalHandle


def fmu_values(model: type, params: Mapping[str, Any] | None = None, n_beacons: int = 4) -> dict[str, Any]:
    """FMU parameter values of a mix of configuration keys and FMU parameters."""
    params = dict(params or {})
    config_names = {v.name for v in model.config_parameters(n_beacons)}
    arrays = {k: v for k, v in params.items() if isinstance(v, np.ndarray) and v.ndim > 0}
    config = {k: (v.reshape(-1)[0].item() if k in arrays else v) for k, v in params.items() if k in config_names}
    extra = {k: v for k, v in params.items() if k not in config_names}
    values = model.fmu_parameters(resolve_parameters(model.config_parameters(n_beacons), config, model.name),
                                  n_beacons)
    values.update(extra)
    values.update(arrays)  # per-replicate values (checked by Component.parameter_matrix)
    return values


class Core:
    """A batch of replicates of one model, stepped by hand.

    Parameters
    ----------
    model : type
        A :class:`sblsim.models.component.Component`.
    params : mapping, optional
        Configuration keys and/or FMU parameters (arrays of shape (B,) per replicate).
    replicates : sequence of int
        ``replicate`` of each row of the batch.
    n_beacons : int
    """

    def __init__(self, model: type, params: Mapping[str, Any] | None = None, replicates: Sequence[int] = (0,),
                 n_beacons: int = 4) -> None:
        self.model = model
        self.replicates = list(replicates)
        self.values = fmu_values(model, params, n_beacons)
        self.handle = LocalHandle(model.name, model, n_beacons)
        self.outputs: dict[str, np.ndarray] = {}

    @property
    def batch(self) -> int:
        return len(self.replicates)

    def initialize(self, t0: float = 0.0) -> "Core":
        self.handle.setup(self.values, self.replicates, t0)
        self.outputs = self.handle.get_outputs()
        return self

    def set_inputs(self, values: Mapping[str, Any]) -> None:
        self.handle.set_inputs({k: np.broadcast_to(np.asarray(v, float), (self.batch,)) for k, v in values.items()})

    def step(self, t: float, h: float) -> dict[str, np.ndarray]:
        self.handle.do_step(t, h)
        self.outputs = self.handle.get_outputs()
        return self.outputs

    @property
    def state(self) -> dict[str, np.ndarray]:
        """The current state by block name, each (B, size)."""
        return self.handle.states()


def _default_signals() -> None:
    # in the child between fork and exec: an ignored signal stays ignored across exec, a default one does not
    for number in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(number, signal.SIG_DFL)


def gauge_free(errors: np.ndarray, at: np.ndarray, scale: bool = False) -> np.ndarray:
    """An array's position errors (R, 2) [m] less their best translation and rotation about ``at``'s centroid (and
    dilation, with ``scale``), by least squares: what no time of arrival sees (the array's shape is what is left)."""
    centred = at - at.mean(axis=0)
    H = np.zeros((2 * len(at), 4 if scale else 3))
    H[0::2, 0] = H[1::2, 1] = 1.0
    H[0::2, 2], H[1::2, 2] = -centred[:, 1], centred[:, 0]
    if scale:
        H[0::2, 3], H[1::2, 3] = centred[:, 0], centred[:, 1]
    v = np.ravel(errors)
    return (v - H @ np.linalg.lstsq(H, v, rcond=None)[0]).reshape(-1, 2)


def shape_rms(errors: np.ndarray, at: np.ndarray, scale: bool = False) -> float:
    """The RMS [m] of :func:`gauge_free` errors."""
    return float(np.sqrt(np.mean(np.sum(gauge_free(errors, at, scale) ** 2, axis=1))))


def start_for_signals(command: Sequence[str], **kwargs: Any) -> subprocess.Popen:
    """``subprocess.Popen(command, **kwargs)`` with SIGINT, SIGTERM and SIGHUP at their defaults in the child.

    A test that sends the child a signal must not inherit the test process's dispositions: in a background
    job (``nohup pytest &``) the shell starts pytest with SIGINT ignored (and nohup SIGHUP), children inherit an
    ignored signal across exec, and sblsim rightly keeps an ignored signal ignored (POSIX only, as the signals are).
    """
    return subprocess.Popen(command, preexec_fn=_default_signals, **kwargs)


def signal_and_wait(proc: subprocess.Popen, sig: int, timeout: float = 60.0) -> tuple[str, str, float]:
    """Send ``proc`` the signal and wait for its end: its standard output and error and the seconds from the signal
    to its end. A process still running after ``timeout`` seconds is killed (the wait's ``TimeoutExpired`` raised),
    as is one the wait is interrupted out of."""
    try:
        sent = time.monotonic()
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=timeout)
        return out, err, time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def share_compiled_objects(cache: Path) -> int:
    """Give the sblsim cache folder ``cache`` (empty: a user's first run) the objects the suite's cache holds, as
    hard links (copies across file systems); the number given.

    A test of what a first run does (build its FMUs and its library into a fresh cache, from a wheel) then links
    the objects the suite compiled once instead of compiling them again: an object is keyed by everything its
    compilation reads (:mod:`sblsim.fmus.compiler`), so a kept one is the one the compiler would make.
    """
    from sblsim.fmus.compiler import cache_dir

    source, target = cache_dir() / "objects", Path(cache) / "objects"
    target.mkdir(parents=True, exist_ok=True)
    shared = 0
    for path in source.glob("*.o") if source.is_dir() else ():
        try:
            os.link(path, target / path.name)
        except OSError:
            shutil.copyfile(path, target / path.name)
        shared += 1
    return shared


__all__ = ["Core", "fmu_values", "share_compiled_objects", "start_for_signals"]


def problem_with(problem: Mapping[str, Mapping[str, Any]], **changes: Mapping[str, Any]) -> dict:
    """A copy of a design problem (section -> keys) with the keys of ``changes`` (section -> keys) set; the original
    untouched."""
    out = {k: dict(v) for k, v in problem.items()}
    for section, values in changes.items():
        out.setdefault(section, {}).update(values)
    return out


def simulated_clocks(n: int, hours: float, seed: int, jump: tuple[int, float, float] | None = None,
                     interval: tuple[float, float] = (540.0, 660.0), **options):
    """A simulated sync array of ``n`` receivers over ``hours`` h (:func:`sblsim.models.sync.simulate.simulate_sync`:
    clocks ±2 s and ±20 ppm, 0.15 ms of timing noise, 3 % multipath echoes, sync tags every ``interval`` [s], one
    clock's ``jump``), its emissions grouped and its clocks fitted with their breaks against receiver 0
    (:func:`sblsim.models.sync.breaks.fit_with_breaks`, ``options`` passed on). Returns the simulation, the time
    origin [s], the times from it, the arrivals used, the emissions, distances [m] and slownesses [s/m], and the
    fit."""
    from sblsim.models.sync.breaks import fit_with_breaks
    from sblsim.models.sync.emissions import connected, sync_emissions
    from sblsim.models.sync.simulate import simulate_sync

    sim = simulate_sync(n_receivers=n, hours=hours, seed=seed, side=800.0, echo_share=0.03, jump=jump,
                        interval=interval)
    origin = np.floor(sim.time.min())
    t = sim.time - origin
    emission, duplicate, single = sync_emissions(sim.tag, sim.receiver, t, np.full(n, 180.0))
    used = ~duplicate & ~single
    distance = np.linalg.norm(sim.positions[sim.tag] - sim.positions[sim.receiver], axis=1)
    linked = connected(sim.receiver[used], emission[used], n, 0)
    slowness = np.full(len(t), 1 / sim.sound_speed)
    fit = fit_with_breaks(sim.receiver, emission, t, distance, slowness, used, linked, 0, 3600.0, sim.tag,
                          **options)
    return sim, origin, t, used, emission, distance, slowness, fit


def check_tag_rows(tags, tracks, given: Sequence[Any] = ()) -> None:
    """Issue 96's invariant on a study's ``tags.csv`` (``tags``) and ``tracks.csv`` (``tracks``), every tag: its
    pings positioned, set aside or not positioned (counts, summing to its pings, the not positioned counted by
    reason); ``tracked`` only with a row positioned, and then its rows in ``tracks.csv`` those positioned (finite
    ``x``, ``y``) and those set aside; any other tag refused with a reason code the study declares and a reason,
    and no row of it in ``tracks.csv``; every option a reason names one ``sblsim track`` has, and every path one of
    ``given`` (the files the study was given)."""
    import argparse
    import re

    import pandas as pd

    from sblsim.models.tracking.strays import SET_ASIDE_REASON
    from sblsim.orchestrator.commands.track import add_arguments
    from sblsim.orchestrator.telemetry.census import REASON_CODES
    from sblsim.orchestrator.telemetry.study import TAG_COLUMNS

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    options = {o for action in parser._actions for o in action.option_strings}
    paths = {str(p) for p in given}
    assert list(tags.columns) == list(TAG_COLUMNS)
    assert len(tags) and tags["tag"].fillna(tags["transmitter"]).is_unique
    for row in tags.itertuples(index=False):
        counts = [row.pings, row.positioned, row.set_aside, row.not_positioned]
        assert all(float(c).is_integer() and c >= 0 for c in counts), row
        assert row.pings == row.positioned + row.set_aside + row.not_positioned, row
        why = "" if pd.isna(row.not_positioned_why) else str(row.not_positioned_why)
        parts = [part.rsplit(" ", 1) for part in why.split("; ") if part]
        assert sum(int(n) for _, n in parts) == row.not_positioned, row
        mine = tracks[tracks["tag"].astype(str) == str(row.tag)]
        reason = "" if pd.isna(row.reason) else str(row.reason)
        if row.status == "tracked":
            assert row.positioned >= 1 and reason == "" and not (isinstance(row.reason_code, str) and row.reason_code)
            placed = mine[["x", "y"]].notna().all(axis=1)
            assert int(placed.sum()) == row.positioned, row
            assert int((mine["quality_reason"] == SET_ASIDE_REASON).sum()) == row.set_aside, row
            assert 0 <= row.flagged <= row.positioned
        else:
            assert row.status == "refused" and row.positioned == 0 and len(mine) == 0, row
            assert row.reason_code in REASON_CODES and reason, row
        for option in re.findall(r"(?<![\w-])--[a-z][a-z-]*", reason):
            assert option in options, (option, reason)
        for path in re.findall(r"'(/[^']*)'", reason):
            assert path in paths, (path, reason)
    assert set(tracks["tag"].astype(str)) == set(tags.loc[tags["status"] == "tracked", "tag"].astype(str))
