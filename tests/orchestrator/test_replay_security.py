"""A log is data: ``sblsim replay`` imports, loads and opens nothing a log names (docs/log-format.md).

Each case runs the command line in a subprocess under an audit hook (:func:`sys.addaudithook`) that records
every ``open`` (reading a file, importing a module's source), ``os.listdir``/``os.scandir`` and
``ctypes.dlopen`` of a path in a folder ``outside`` beside the working folder, which holds a receiver model
that writes a canary file when imported, a valid trajectory file, a valid sound-speed profile and an "FMU".
The log (CSV ``#%`` lines or Parquet metadata) names them. Two controls show that the hook sees what it
must: the same model and trajectory given on the command line are opened (and the model imported).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import tomli_w

from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run
from sblsim.orchestrator.io.log_tables import CONFIG_PREFIX, META_CONFIG
from sblsim.orchestrator.logs.log_export import export_log
from sblsim.orchestrator.logs.receiver_log import log_config

#: The log's two formats where a test is the same property read by another reader: the Parquet run in the slow tier
#: (the fast tier keeps every property once, on the CSV; the tests of both formats that stay fast read Parquet too).
SUFFIXES_FAST_CSV = [".csv", pytest.param(".parquet", marks=pytest.mark.slow)]

#: The audited command: argv = outside folder, report file, sblsim arguments.
AUDITED = r"""
import atexit, json, os, sys
outside, report, args = os.path.realpath(sys.argv[1]), sys.argv[2], sys.argv[3:]
seen, busy = [], [False]
def hook(event, detail):
    if busy[0] or event not in ("open", "os.listdir", "os.scandir", "ctypes.dlopen"):
        return
    busy[0] = True
    try:
        path = detail[0] if detail else None
        if isinstance(path, (str, bytes, os.PathLike)):
            name = os.path.realpath(os.path.abspath(os.fsdecode(path)))
            if name == outside or name.startswith(outside + os.sep):
                seen.append([event, name])
    finally:
        busy[0] = False
def write():
    with open(report, "w") as handle:
        json.dump(seen, handle)
atexit.register(write)
sys.addaudithook(hook)
from sblsim.orchestrator.cli import main
sys.exit(main(args))
"""

MODEL = 'from pathlib import Path\nPath(__file__).with_name("CANARY").write_text("imported")\n'
TRAJECTORY = "time,north,east,down\n0,0,0,5\n10,5,5,5\n"
PROFILE = "depth,sound_speed\n0,1500\n100,1490\n"


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The CSV and Parquet logs of a short semicircle run."""
    base = tmp_path_factory.mktemp("exported")
    result = run(load_config("semicircle", ["simulation.duration=3"], seed=2))
    return {suffix: export_log(result, base / f"log{suffix}")[0] for suffix in (".csv", ".parquet")}


def hostile_log(source: Path, folder: Path, edit) -> Path:
    """A copy of an exported log in ``folder`` whose configuration ``edit(raw)`` changed (CSV lines or Parquet
    metadata)."""
    raw = tomllib.loads(log_config(source))
    edit(raw)
    text = tomli_w.dumps(raw)
    target = folder / source.name
    if source.suffix == ".csv":
        lines = [line for line in source.read_text().split("\n") if not line.startswith("#%")]
        config = [f"{CONFIG_PREFIX}{line}" for line in text.splitlines()]
        target.write_text("\n".join(config + lines))
    else:
        table = pq.read_table(source)
        meta = {**(table.schema.metadata or {}), META_CONFIG: text.encode()}
        pq.write_table(table.replace_schema_metadata(meta), target)
    return target


@pytest.fixture
def folders(tmp_path):
    """``work`` (the working folder) and ``outside`` with the files a log may name."""
    work, outside = tmp_path / "work", tmp_path / "outside"
    work.mkdir()
    outside.mkdir()
    (outside / "evil.py").write_text(MODEL)
    (outside / "track.csv").write_text(TRAJECTORY)
    (outside / "profile.csv").write_text(PROFILE)
    (outside / "evil.fmu").write_bytes(b"PK\x05\x06" + bytes(18))
    return work, outside


def audited(work: Path, outside: Path, *args: str, watch: Path | None = None):
    """Run sblsim in ``work``; returns (process, the recorded accesses of ``watch`` (default ``outside``))."""
    report = work.parent / "report.json"
    proc = subprocess.run([sys.executable, "-c", AUDITED, str(watch or outside), str(report), *args], cwd=work,
                          capture_output=True, text=True, timeout=600)
    return proc, json.loads(report.read_text()) if report.exists() else None


def set_receiver(value):
    def edit(raw):
        raw["simulation"]["receiver"] = value
    return edit


def assert_one_line(proc, needle):
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("sblsim: error:") and needle in lines[0], proc.stderr


@pytest.mark.parametrize("suffix", SUFFIXES_FAST_CSV)
def test_a_log_naming_a_model_is_refused_and_never_imported(exported, folders, suffix):
    work, outside = folders
    log = hostile_log(exported[suffix], work, set_receiver(f"model:{outside / 'evil.py'}"))
    proc, seen = audited(work, outside, "replay", log.name, "--out", "r")
    assert_one_line(proc, "simulation.receiver")
    assert seen == [] and not (outside / "CANARY").exists()
    assert sorted(p.name for p in work.iterdir()) == [log.name]  # nothing written


@pytest.mark.parametrize("suffix", SUFFIXES_FAST_CSV)
def test_a_relative_model_beside_the_log_is_not_imported(exported, folders, suffix):
    """The log and the model came together and are replayed from their folder: the model stays unread."""
    work, outside = folders
    (work / "evil.py").write_text(MODEL)
    log = hostile_log(exported[suffix], work, set_receiver("model:evil.py"))
    proc, seen = audited(work, outside, "replay", log.name, "--out", "r", watch=work / "evil.py")
    assert_one_line(proc, "model:evil.py")
    assert seen == [] and not (work / "CANARY").exists()


@pytest.mark.slow
@pytest.mark.parametrize("suffix", SUFFIXES_FAST_CSV)
@pytest.mark.parametrize("switch", [["--receiver", "ekf"], ["--set", "receiver=ekf-seq"]], ids=["receiver", "set"])
def test_switching_receivers_does_not_import_the_logs(exported, folders, suffix, switch):
    work, outside = folders
    log = hostile_log(exported[suffix], work, set_receiver(f"model:{outside / 'evil.py'}"))
    proc, seen = audited(work, outside, "replay", log.name, "--out", "r", *switch)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert seen == [] and not (outside / "CANARY").exists()
    config = tomllib.loads((work / "r" / "config.toml").read_text())
    assert config["simulation"]["receiver"] == switch[1].split("=")[-1]


@pytest.mark.slow
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_log_naming_an_fmu_is_refused_and_never_loaded(exported, folders, suffix):
    work, outside = folders
    log = hostile_log(exported[suffix], work, set_receiver(f"fmu:{outside / 'evil.fmu'}"))
    proc, seen = audited(work, outside, "replay", log.name, "--out", "r")
    assert_one_line(proc, "an FMU")
    assert seen == []
    proc, seen = audited(work, outside, "replay", log.name, "--out", "r", "--receiver", "ukf")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert seen == []


@pytest.mark.slow
@pytest.mark.parametrize("suffix", SUFFIXES_FAST_CSV)
def test_files_a_log_names_are_not_opened(exported, folders, suffix):
    work, outside = folders

    def edit(raw):
        raw["target"].update(trajectory="file", trajectory_file=str(outside / "track.csv"))
        raw["acoustics"]["sound_speed_profile"] = str(outside / "profile.csv")

    log = hostile_log(exported[suffix], work, edit)
    proc, seen = audited(work, outside, "replay", log.name, "--out", "r")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert seen == []
    notes = [line for line in proc.stderr.splitlines() if line.startswith("note:")]
    assert len(notes) == 2 and "target.trajectory_file" in notes[0] and "sound_speed_profile" in notes[1]
    assert str(outside) not in proc.stderr + proc.stdout  # no path, no content of those files is echoed
    config = tomllib.loads((work / "r" / "config.toml").read_text())
    assert config["target"]["trajectory_file"] == "" and config["acoustics"]["sound_speed_profile"] == "constant"


@pytest.mark.slow
@pytest.mark.parametrize("suffix", SUFFIXES_FAST_CSV)
def test_a_logs_receiver_naming_a_private_csv_is_refused_unopened(exported, folders, suffix):
    """``receiver.sound_speed_profile`` is a file key as the channel's is: a log naming a CSV there is refused in one
    line (a replay needs the receiver's profile, so none is put in its place), the file never opened, nothing
    written; the user's own ``--set`` of the key replaces it."""
    work, outside = folders

    def edit(raw):
        raw["receiver"]["sound_speed_profile"] = str(outside / "profile.csv")

    log = hostile_log(exported[suffix], work, edit)
    proc, seen = audited(work, outside, "replay", log.name, "--out", "r")
    assert_one_line(proc, "receiver.sound_speed_profile")
    assert seen == [] and str(outside) not in proc.stderr
    assert sorted(p.name for p in work.iterdir()) == [log.name]  # nothing written
    proc, seen = audited(work, outside, "replay", log.name, "--out", "r", "--set",
                         "receiver.sound_speed_profile=assumed")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert seen == []
    assert tomllib.loads((work / "r" / "config.toml").read_text())["receiver"]["sound_speed_profile"] == "assumed"


@pytest.mark.slow
def test_controls_the_hook_sees_a_model_and_a_file_given_on_the_command_line(exported, folders):
    """What the user names is used, and said: the model is imported (the canary) and its file opened, the
    trajectory file read; so the empty records above are not the hook's blindness."""
    work, outside = folders
    log = hostile_log(exported[".csv"], work, lambda raw: None)
    model = f"model:{outside / 'evil.py'}"
    proc, seen = audited(work, outside, "replay", log.name, "--out", "r", "--receiver", model)
    assert proc.returncode == 2  # evil.py defines no receiver: refused, but only after importing it
    assert (outside / "CANARY").read_text() == "imported"
    assert ["open", str((outside / "evil.py").resolve())] in seen
    (outside / "CANARY").unlink()
    proc, seen = audited(work, outside, "run", "semicircle", "--out", "o", "--set", "target.trajectory=file",
                         "--set", f"target.trajectory_file={outside / 'track.csv'}")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert ["open", str((outside / "track.csv").resolve())] in seen


@pytest.mark.slow
def test_the_receiver_a_user_names_is_said(exported, tmp_path):
    model = Path(__file__).resolve().parents[2] / "docs" / "examples" / "constant_position.py"
    proc = subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", "replay", str(exported[".csv"]),
                           "--out", str(tmp_path / "r"), "--receiver", f"model:{model}"], capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert f"note: the receiver is your own program, model:{model} (--receiver)" in proc.stderr


@pytest.mark.parametrize("name", ["../../escape", *(pytest.param(n, marks=pytest.mark.slow) for n in
                                                    ("/tmp/absolute-escape", "a/../../b", "..", "sub\\..\\x"))])
def test_a_scenario_name_never_leaves_results(tmp_path, name):
    """``run.scenario`` of a configuration file is anyone's text: the default folder is one name in results/."""
    work = tmp_path / "deep" / "work"
    work.mkdir(parents=True)
    (work / "c.toml").write_text(tomli_w.dumps({"run": {"scenario": name}, "simulation": {"duration": 1.0}}))
    before = {p for p in tmp_path.rglob("*")}
    proc = subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", "run", "c.toml"], cwd=work,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    new = {p for p in tmp_path.rglob("*")} - before
    folders = {p.relative_to(work).parts[:2] for p in new}
    assert len(folders) == 2 and all(f[0] == "results" for f in folders), new  # results/ and results/<one name>
    assert not Path("/tmp/absolute-escape").exists()
    written = next(f[1] for f in folders if len(f) == 2)
    assert "/" not in written and "\\" not in written and not written.startswith(".")
    assert os.path.isfile(work / "results" / written / "summary.json")


def test_a_study_name_never_leaves_results(tmp_path):
    work = tmp_path / "deep" / "work"
    work.mkdir(parents=True)
    (work / "s.toml").write_text('[study]\nname = "../../escape"\nscenarios = ["semicircle"]\nreplicates = 1\n'
                                 'set = ["simulation.duration=1"]\n[[factors]]\nname = "b"\n'
                                 'key = "platform.baseline"\nlow = 1\nhigh = 3\n')
    proc = subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", "campaign", "s.toml", "--workers", "1"],
                          cwd=work, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["deep"] and sorted(p.name for p in work.iterdir()) == [
        "results", "s.toml"]
    assert [p.name for p in (work / "results").iterdir()] == ["_.._escape"]
