"""Many tags at one array, tracked in parallel: one times-of-arrival file per tag, each tracked by
:func:`~sblsim.orchestrator.tracks.track.track` in a worker of its own (a pool of worker processes on this machine,
or a Dask cluster's workers, :mod:`sblsim.orchestrator.campaign.executors`), as a campaign runs its chunks.

The tags' folders and ``tags.csv`` (one row per tag: whether it was tracked or refused and why, its pings, the rows
set aside as no pings of its schedule, positioned and flagged (a set-aside row in neither), the sound speed and ping
type taken, its time) are written together, all or nothing, when every tag has ended; a tag whose file is refused is
a row saying so, never the end of the others.
:func:`replay_toa_tags` (``sblsim.replay_toa_tags``, ``sblsim replay FOLDER --format toa``) checks its arguments and
returns a :class:`TagsResult`.
"""

from __future__ import annotations

import multiprocessing
import os
import tempfile
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

from sblsim.models.declarations import ModelError
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.io.arguments import path_argument, prepare_out, real_argument
from sblsim.orchestrator.io.memory import release
from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.tracks.options import TOA_OPTIONS, toa_options
from sblsim.orchestrator.tracks.outcome import TrackOutcome
from sblsim.orchestrator.tracks.outputs import write
from sblsim.orchestrator.tracks.replay import TrackResult
from sblsim.orchestrator.tracks.resume import Resume, job_key, write_entry
from sblsim.orchestrator.tracks.track import track

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd

#: The most tags one call tracks.
MAX_TAGS = 10_000
#: The file names taken as one tag's times of arrival in a folder.
TAG_SUFFIXES = (".txt", ".csv", ".toa")
#: The columns of ``tags.csv``.
TAG_COLUMNS = ("tag", "status", "reason", "pings", "set_aside", "positioned", "flagged", "share_flagged",
               "track", "sound_speed_m_s", "sound_speed_source", "ping_type", "segments", "wall_time_s")


@dataclass
class TagsOutcome:
    """What :func:`track_tags` returns: ``table`` (``tags.csv``: :data:`TAG_COLUMNS`, one row per tag, in the
    files' order) and ``outcomes`` (tag name → its :class:`~sblsim.orchestrator.tracks.outcome.TrackOutcome`, the
    tracked tags only)."""

    table: Any  # pandas.DataFrame
    outcomes: dict[str, Any]


def tag_files(folder: Path) -> list[Path]:
    """The tag files of a folder: its regular files named ``*.txt``, ``*.csv`` or ``*.toa`` (not a symbolic link, not
    hidden), sorted by name, one tag each (named by the file's stem).

    Raises
    ------
    ModelError
        No such file, more than :data:`MAX_TAGS`, or two files of one stem.
    """
    folder = Path(folder)
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in TAG_SUFFIXES and not p.name.startswith(".")
                   and not p.is_symlink() and p.is_file())
    if not files:
        raise ModelError(f"toa: {str(folder)!r} holds no tag file; allowed: a folder of one times-of-arrival file "
                         f"per tag ({', '.join('*' + s for s in TAG_SUFFIXES)})")
    if len(files) > MAX_TAGS:
        raise ModelError(f"toa: {str(folder)!r} holds {len(files):,} tag files; allowed at most {MAX_TAGS:,}")
    stems = [p.stem for p in files]
    twice = next((s for s in stems if stems.count(s) > 1), None)
    if twice is not None:
        raise ModelError(f"toa: two tag files named {twice!r} in {str(folder)!r}; allowed: one file per tag name")
    return files


def track_tag(toa_path: Path, receivers: Path, options: dict[str, Any]):
    """One tag tracked (:func:`~sblsim.orchestrator.tracks.track.track` with ``options``): its outcome, or the one
    line of its refusal (a :class:`ModelError`, or any other fault, named as one)."""
    try:
        return track(toa_path, receivers, **options)
    except ModelError as exc:
        return str(exc)
    except Exception as exc:  # a fault of ours on this tag's data: said in its row, the other tags go on
        return f"internal error ({type(exc).__name__}: {' '.join(str(exc).split())[:200]}); please report it"


def track_finished(toa_path: Path, receivers: Path, options: dict[str, Any], entry: Path | None = None,
                   finish: Callable[[Any], Any] | None = None) -> tuple[Any, tuple[str, str] | None]:
    """:func:`track_tag` in a worker process that shares the caller's filesystem: its outcome kept for a rerun there
    (``entry``: :meth:`~sblsim.orchestrator.tracks.resume.Resume.staging`'s folder), then given to ``finish``
    there (e.g. its files written and what is sent back cut to what the caller keeps:
    :func:`~sblsim.orchestrator.tracks.outputs.written_main`). Returns what ``finish`` made of the outcome, and
    why the entry could not be kept (:func:`~sblsim.orchestrator.tracks.resume.filled`) or None."""
    result = track_tag(toa_path, receivers, options)
    unkept = None if entry is None else write_entry(entry, result, toa_path.parent)
    return (result if finish is None else finish(result)), unkept


def _row(name: str, result, elapsed: float) -> dict[str, Any]:
    if isinstance(result, str):
        return {"tag": name, "status": "refused", "reason": result, "wall_time_s": elapsed}
    s = result.summary
    main = s["track"]
    aside = int(s.get("set_aside", {}).get("count", 0))  # rows no ping of the tag's schedule: no estimate
    positioned = s["fixed"].get(main, 0) - aside
    flagged = s["flagged"].get(main, 0) - aside
    return {"tag": name, "status": "tracked", "reason": "", "pings": s["pings"], "set_aside": aside,
            "positioned": positioned,
            "flagged": flagged, "share_flagged": flagged / positioned if positioned else 0.0, "track": main,
            "sound_speed_m_s": s["sound_speed"]["sound_speed_m_s"], "sound_speed_source": s["sound_speed"]["source"],
            "ping_type": s["ping_type"]["type"], "segments": len(s["segments"]), "wall_time_s": s["wall_time_s"]}


def _relocated(value: Any, moves: dict[str, str]) -> Any:
    """``value`` (a refusal's line, or an outcome's summary within) with each folder of ``moves`` named as its
    value (a worker's copies of the files named as the files it was sent)."""
    if isinstance(value, str):
        for there, here in moves.items():
            value = value.replace(there, here)
        return value
    if isinstance(value, dict):
        return {k: _relocated(v, moves) for k, v in value.items()}
    if isinstance(value, list):
        return [_relocated(v, moves) for v in value]
    if isinstance(value, TrackOutcome):
        return replace(value, summary=_relocated(value.summary, moves))
    return value


def sent_files(toa: Path, receivers: Path, options: dict[str, Any]) -> dict[str, tuple[str, bytes]]:
    """The files one tag's track reads, as sent to a worker that shares no filesystem with this process: role (``toa``,
    ``receivers`` or the option's name) → (the file's path here, its bytes)."""
    files = {"toa": toa, "receivers": receivers} | {k: v for k, v in options.items() if isinstance(v, Path)}
    return {role: (str(path), Path(path).read_bytes()) for role, path in files.items()}


def track_sent(files: dict[str, tuple[str, bytes]], options: dict[str, Any]):
    """:func:`track_tag` on a worker of its own files (:func:`sent_files`): each written in a temporary folder of the
    worker, tracked, and named in the outcome as it is named here, so that the outcome is the one this process would
    make."""
    with tempfile.TemporaryDirectory(prefix="sblsim-tag-") as tmp:
        paths, moves = {}, {}
        for role, (name, data) in files.items():
            folder = Path(tmp) / role
            folder.mkdir()
            paths[role] = folder / Path(name).name
            paths[role].write_bytes(data)
            moves[str(folder)] = str(Path(name).parent)
        mine = {k: paths.get(k, v) for k, v in options.items()}
        return _relocated(track_tag(paths["toa"], paths["receivers"], mine), moves)


def run_tracks(jobs: Sequence[tuple[str, Path, Path, dict[str, Any]]], workers: int | None = None,
               scheduler: str | None = None, ended: Callable[[str, Any], None] | None = None,
               resume: Resume | None = None, finish: dict[str, Callable[[Any], Any]] | None = None
               ) -> dict[str, Any]:
    """Track each job ``(name, toa_path, receivers_path, options)`` (:func:`track_tag`, each with its own options) in
    worker processes (``workers``, default the CPU count; 1: one after another in this process) or on a Dask
    scheduler's workers (each sent its tag's files: :func:`track_sent`, no shared filesystem assumed); ``ended(name,
    result)`` called as each ends (what it returns, where not None, kept in the result's place: a study that wrote
    the tag's files keeps its track alone). With ``resume``, a tag kept by an interrupted run of the same inputs is
    taken from it (:mod:`.resume`) and each tag that ends is kept. ``finish`` (name → a picklable function) is applied
    to that tag's outcome (kept whole for a rerun first) before ``ended`` sees it: in its worker process where the
    workers are this machine's (:func:`track_finished`: a season's tag not sent back whole), else here. Returns
    name → the :class:`~sblsim.orchestrator.tracks.outcome.TrackOutcome`, or the one line of its refusal."""
    results: dict[str, Any] = {}
    keys: dict[str, tuple[str, Path]] = {}
    finish = finish or {}

    def done(name: str, result, finished: bool = False) -> None:  # (finished: kept and finished by its worker)
        if resume is not None and name in keys and not finished:
            resume.save(keys[name][0], result, keys[name][1])
        if name in finish and not finished:
            result = finish[name](result)
        kept = None if ended is None else ended(name, result)
        results[name] = result if kept is None else kept
        release()  # what the tag's result took, unpickled and written, handed back (a season's tags one by one)

    if resume is not None:
        left = []
        for job in jobs:
            name, toa, receivers, options = job
            key = job_key(toa, receivers, options)
            kept = resume.load(key, toa.parent)
            if kept is None:
                keys[name] = (key, toa.parent)
                left.append(job)
            else:
                done(name, kept)
        jobs = left
    if not jobs:
        return results
    workers = workers or os.cpu_count() or 1
    if scheduler is not None:
        from sblsim.orchestrator.campaign.executors import close_client, connect

        client = connect(scheduler, workers=workers)
        try:
            from distributed import as_completed

            futures = {client.submit(track_sent, sent_files(toa, receivers, options), options, pure=False): name
                       for name, toa, receivers, options in jobs}
            for future in as_completed(futures, loop=client.loop):
                name, result = futures.pop(future), future.result()
                future = None  # released: its result not held by the cluster while the others are tracked
                done(name, result)
                result = None
        finally:
            close_client(client)
    elif workers == 1 or len(jobs) == 1:
        for name, toa, receivers, options in jobs:
            done(name, track_tag(toa, receivers, options))
    else:
        from sblsim.orchestrator.campaign.executors import stop_pool
        from sblsim.orchestrator.campaign.worker import watch_parent

        pool = ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=multiprocessing.get_context("spawn"),
                                   initializer=watch_parent, initargs=(os.getpid(),))
        all_done = False  # (not `ended`: the callback's name, which done() calls)
        try:
            pending = {}
            for name, toa, receivers, options in jobs:  # each kept for a rerun and finished by its worker
                staged = resume.staging(keys[name][0]) if resume is not None and name in keys else None
                pending[pool.submit(track_finished, toa, receivers, options, staged, finish.get(name))] = name, staged
            while pending:
                finished = wait(pending, return_when=FIRST_COMPLETED)[0]
                while finished:  # each ended tag's result held by no future while the next are awaited
                    future = finished.pop()
                    (name, staged), (result, unkept) = pending.pop(future), future.result()
                    future = None
                    if staged is not None:
                        resume.adopt(keys[name][0], staged, unkept)
                    done(name, result, finished=True)
                    result = None
            all_done = True
        finally:
            if not all_done:  # stopped (while submitting too) or failed: the tags under way stopped, not awaited
                stop_pool(pool)
            else:
                pool.shutdown()
    return results


def track_tags(files: Sequence[Path], receivers: Path, options: dict[str, Any], workers: int | None = None,
               scheduler: str | None = None, out: Path | None = None,
               progress: Callable[[dict[str, Any], int, int], None] | None = None) -> TagsOutcome:
    """Track each tag file at the array of ``receivers`` (module docstring).

    Parameters
    ----------
    files : sequence of Path
        One times-of-arrival file per tag (:func:`tag_files`), the tag named by the file's stem.
    receivers : Path
        The receivers' positions, shared by every tag.
    options : dict
        Keyword arguments of :func:`~sblsim.orchestrator.tracks.track.track`, the same for every tag.
    workers : int, optional
        Worker processes on this machine (default the CPU count; 1: in this process, one tag after another).
    scheduler : str, optional
        A Dask scheduler (``tcp://HOST:PORT``, or ``local`` for a local cluster of ``workers``): the tags run on its
        workers instead.
    out : Path, optional
        Write each tracked tag's folder (``out/TAG/``, as ``sblsim replay --format toa``) and ``tags.csv`` there,
        all or nothing when every tag has ended; each tag is kept as it ends (:mod:`.resume`), so that a run
        interrupted and made again with the same inputs tracks only the tags it had not finished.
    progress : callable, optional
        Called with each tag's row, the tags ended and their number, as each ends.

    Returns
    -------
    TagsOutcome
    """
    import pandas as pd

    files = [Path(f) for f in files]
    names = [f.stem for f in files]
    started = time.perf_counter()
    rows: dict[str, dict[str, Any]] = {}

    def ended(name: str, result) -> None:
        rows[name] = _row(name, result, time.perf_counter() - started)
        if progress is not None:
            progress(rows[name], len(rows), len(files))

    resume = None if out is None else Resume(out)
    results = run_tracks([(n, f, Path(receivers), options) for f, n in zip(files, names)], workers, scheduler, ended,
                         resume)
    table = pd.DataFrame([rows[n] for n in names], columns=list(TAG_COLUMNS))
    outcomes = {n: r for n, r in results.items() if not isinstance(r, str)}
    if out is not None:
        with staged_directory(out) as tmp:
            for name, outcome in outcomes.items():
                write(outcome, tmp / name)
            table.to_csv(tmp / "tags.csv", index=False)
        resume.remove()
    return TagsOutcome(table, outcomes)


__all__ = ["MAX_TAGS", "TAG_COLUMNS", "TAG_SUFFIXES", "TagsOutcome", "run_tracks", "tag_files", "track_tag",
           "track_tags"]


@dataclass
class TagsResult:
    """The outcome of :func:`replay_toa_tags`.

    Attributes
    ----------
    table : pandas.DataFrame
        ``tags.csv``: one row per tag (``tag``, ``status`` ``tracked`` or ``refused``, ``reason``, ``pings``,
        ``set_aside``, ``positioned``, ``flagged``, ``share_flagged``, ``track`` (the estimator), ``sound_speed_m_s``,
        ``sound_speed_source``, ``ping_type``, ``segments``, ``wall_time_s``).
    tracks : dict of str to TrackResult
        Each tracked tag's result, by its name.
    out : Path or None
    """

    table: pd.DataFrame
    tracks: dict[str, TrackResult]
    out: Path | None = None


def replay_toa_tags(folder: str | Path, *, receivers: str | Path, workers: int | None = None,
                    scheduler: str | None = None, out: str | Path | None = None, force: bool = False,
                    **options: Any) -> TagsResult:
    """Track many tags at one array in parallel: ``sblsim replay FOLDER --format toa`` (docs/tracking.md).

    Parameters
    ----------
    folder : str or Path
        A folder of one times-of-arrival file per tag (``*.txt``, ``*.csv``, ``*.toa``; the tag named by the
        file's stem), each as :func:`~sblsim.orchestrator.tracks.replay.replay_toa` reads one.
    receivers : str or Path
        The receivers' positions, shared by the tags.
    workers : int, optional
        Worker processes in [1, 256] (default the CPU count; 1: one tag after another in this process).
    scheduler : str, optional
        A Dask scheduler, ``tcp://HOST:PORT`` or ``local``: the tags run on its workers.
    out : str or Path, optional
        Write each tag's folder (``out/TAG/``) and ``tags.csv`` there, all or nothing.
    force : bool
        Replace an earlier result in ``out``.
    **options
        :func:`~sblsim.orchestrator.tracks.replay.replay_toa`'s tracking arguments (``smooth``, ``sound_speed``,
        ``ping_type``, ...), the same for every tag; no ``truth`` or ``reference`` (one per tag).

    Returns
    -------
    TagsResult

    Raises
    ------
    ModelError, ConfigError
        A folder without tag files, a bad option (one line). A tag whose own file is refused is a row of
        ``tags.csv`` (``status`` ``refused``, the reason), the others tracked.
    """
    folder = path_argument(folder, "folder", optional=False)
    receivers = path_argument(receivers, "receivers", optional=False)
    if not folder.is_dir():
        raise ConfigError(f"folder: {str(folder)!r} is not a folder; allowed: a folder of one times-of-arrival file "
                          "per tag (replay_toa tracks one file)")
    unknown = sorted(set(options) - set(TOA_OPTIONS))
    if unknown or "truth_sigma" in options:
        raise ConfigError(f"{(unknown or ['truth_sigma'])[0]}: not an option of replay_toa_tags; allowed: "
                          f"{', '.join(k for k in TOA_OPTIONS if k != 'truth_sigma')}")
    if workers is not None:
        workers = int(real_argument(workers, "workers", 1, 256, ""))
    if scheduler is not None:
        from sblsim.orchestrator.campaign.executors import check_address

        scheduler = check_address(str(scheduler))
    files = tag_files(folder)
    target = prepare_out(out, force, "tags.csv", "tags")
    done = track_tags(files, receivers, toa_options(**options), workers, scheduler, target)
    return TagsResult(done.table, {name: TrackResult(o.track, o.score, o.summary, o.estimates, o.errors,
                                                     None if target is None else target / name, o.bound)
                                   for name, o in done.outcomes.items()}, target)
