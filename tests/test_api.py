"""The public Python API (``import sblsim``) gives the command line's numbers, raises instead of exiting, and
imports cheaply.

The command line is the reference: each case runs ``sblsim ...`` (its ``main``, writing its files into a
temporary folder) and the API function, and compares the files the command wrote with the API's objects.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.systems import system_overrides

SCENARIOS = ("semicircle", "spiral", "random", "square", "harbour", "random-walk")
SYSTEMS = ("sbl", "lbl", "usbl")
RECEIVERS = ("ekf", "ekf-seq", "ukf", "lsq")
SHORT = "simulation.duration=15"  # every case runs 150 steps: the comparison is exact, whatever the length


def cli_run(tmp_path: Path, scenario: str, items: list[str], seed: int, engine: str = "local",
            fmu_dir: Path | None = None) -> tuple[dict, pd.DataFrame]:
    out = tmp_path / "cli"
    args = ["run", scenario, "--seed", str(seed), "--out", str(out), "--engine", engine]
    args += [a for item in items for a in ("--set", item)]
    args += ["--fmu-dir", str(fmu_dir)] if fmu_dir is not None else []
    assert main(args) == 0
    return json.loads((out / "summary.json").read_text()), pd.read_parquet(out / "timeseries.parquet")


def assert_same_run(tmp_path, scenario, items, seed=3, engine="local", fmu_dir=None):
    summary, series = cli_run(tmp_path, scenario, items, seed, engine, fmu_dir)
    r = sblsim.run(scenario, seed=seed, set=items, engine=engine, fmu_dir=fmu_dir)
    mine = dict(r.summary)
    assert mine.pop("wall_time") >= 0 and summary.pop("wall_time") >= 0
    assert mine == summary  # every key, every number bit for bit
    pd.testing.assert_frame_equal(r.timeseries, series, check_exact=True)
    return r


@pytest.mark.slow
@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("system", SYSTEMS)
def test_api_run_is_the_cli_run_for_every_scenario_and_system(tmp_path, scenario, system):
    items = system_overrides(system, [SHORT]) if system != "sbl" else [SHORT]
    r = assert_same_run(tmp_path, scenario, items)
    assert r.config["platform"]["system"] == system and r.steps == 150


@pytest.mark.slow
@pytest.mark.parametrize("system", SYSTEMS)
@pytest.mark.parametrize("receiver", RECEIVERS)
def test_api_run_is_the_cli_run_for_every_receiver(tmp_path, system, receiver):
    items = [SHORT, f"simulation.receiver={receiver}"]
    items = system_overrides(system, items) if system != "sbl" else items
    r = assert_same_run(tmp_path, "semicircle", items, seed=5)
    assert r.summary["receiver"] == receiver


@pytest.mark.slow
def test_api_run_on_the_fmu_engine_is_the_cli_run(tmp_path, fmu_dir):
    assert_same_run(tmp_path, "spiral", [SHORT, "simulation.receiver=ukf"], seed=2, engine="fmu", fmu_dir=fmu_dir)


def test_a_mapping_of_overrides_is_the_set_items(tmp_path):
    """``set={"platform.baseline": 0.4}`` is ``--set platform.baseline=0.4``; a text stays a text."""
    a = sblsim.load("semicircle", seed=7, set={"platform.baseline": 0.4, "receiver": "lsq", "target.depth": 12})
    b = sblsim.load("semicircle", seed=7, set=["platform.baseline=0.4", "receiver=lsq", "target.depth=12"])
    assert a == b and a["platform"]["baseline"] == 0.4 and a["simulation"]["receiver"] == "lsq"
    assert sblsim.load(a) == a  # a configuration is validated again, unchanged
    assert sblsim.load(a, set={"target.depth": 20})["target"]["depth"] == 20


def test_replicates_are_the_runs_of_each_replicate_alone():
    both = sblsim.run("semicircle", replicates=2, set=[SHORT])
    for k, s in enumerate(both.summaries):
        alone = sblsim.run("semicircle", set=[SHORT, f"run.replicate={k}"]).summary
        assert {**s, "wall_time": 0} == {**alone, "wall_time": 0}


@pytest.mark.slow
def test_nothing_is_written_without_out_and_the_files_with_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = sblsim.run("semicircle", set=[SHORT])
    assert list(tmp_path.iterdir()) == []
    figures = r.plot()
    assert set(figures) == {"trajectory_xy", "trajectory_3d", "errors", "error_bounds"}
    assert all(type(f).__name__ == "Figure" for f in figures.values())
    r = sblsim.run("semicircle", set=[SHORT], out="here")
    assert json.loads((tmp_path / "here" / "summary.json").read_text())["e_tot_rms"] == r.summary["e_tot_rms"]
    with pytest.raises(sblsim.SblsimError, match="out: .* holds an earlier run; pass force=True"):
        sblsim.run("semicircle", set=[SHORT], out="here")


@pytest.mark.parametrize("call, needle", [
    (lambda: sblsim.load("no-such-scenario"), "no-such-scenario"),
    (lambda: sblsim.run("semicircle", set={"platform.baseline": -1.0}), "platform.baseline"),
    (lambda: sblsim.run("semicircle", seed=-1), "seed"),
    (lambda: sblsim.run("semicircle", engine="gpu"), "engine"),
    (lambda: sblsim.run("semicircle", replicates=0), "replicates"),
    (lambda: sblsim.load("semicircle", set="platform.baseline=1"), "set"),
    (lambda: sblsim.compare("semicircle", receivers=["ekf", "nope"]), "nope"),
    (lambda: sblsim.accuracy_map("semicircle", levels=["x"]), "levels"),
    (lambda: sblsim.budget("semicircle", replicates=1), "replicates"),
    (lambda: sblsim.calibrate("xie-2021-07-23", replicates=2), "replicates"),
    (lambda: sblsim.calibrate("box-in", format="xie"), "format"),
    (lambda: sblsim.calibrate("box-in", replicates=0), "replicates"),
    (lambda: sblsim.calibrate("box-in", set={"survey.radius_m": -1.0}), "survey.radius_m"),
])
def test_bad_input_raises_an_sblsim_error_not_system_exit(call, needle):
    with pytest.raises(sblsim.SblsimError) as caught:
        call()
    message = str(caught.value)
    assert needle in message and "\n" not in message


#: Each argument of the API given what its docstring does not allow (issue 42's corpus and the like): the documented
#: error class (an SblsimError), one line starting with the argument's name, raised at the boundary (before any
#: work: none of these calls may run long enough to notice).
HOSTILE = {
    "run out=1": (lambda: sblsim.run("semicircle", out=1), "out: 1 is not a file or folder"),
    "run force='no'": (lambda: sblsim.run("semicircle", out="o", force="no"), "force: 'no' is not True or False"),
    "run fmu_dir=2.5": (lambda: sblsim.run("semicircle", fmu_dir=2.5), "fmu_dir: 2.5 is not a file or folder"),
    "run set=1": (lambda: sblsim.run("semicircle", set=1), "set: expected a mapping"),
    "run engine array": (lambda: sblsim.run("semicircle", engine=np.array(["local", "fmu"])), "engine:"),
    "run progress 'x'": (lambda: sblsim.run("semicircle", progress="x"), "progress: 'x' is not True, False"),
    "map extent 'x'": (lambda: sblsim.accuracy_map("semicircle", extent="x"),
                       "extent: 'x' is not a number; allowed: (0, 100000] m"),
    "map extent beyond 100 km": (lambda: sblsim.accuracy_map("semicircle", extent=2e5, step=1e5),
                                 "extent: 200000.0 is outside the allowed range (0, 100000] m"),
    "map step array": (lambda: sblsim.accuracy_map("semicircle", step=np.array([1.0, 2.0])),
                       "step: a numpy array of shape (2,) is not a number"),
    "map step nan": (lambda: sblsim.accuracy_map("semicircle", step=float("nan")),
                     "step: nan is outside the allowed range (0, 30] m"),
    "map compare values None": (lambda: sblsim.accuracy_map("semicircle", compare=("platform.baseline", None)),
                                "compare: the values of platform.baseline must be a list"),
    "map depth 'x'": (lambda: sblsim.accuracy_map("semicircle", depth="x"), "depth: 'x' is not a number"),
    "map depth below the site": (lambda: sblsim.accuracy_map("lbl-field", depth=301.0),
                                 "depth: 301 m is outside the allowed range [0, 300) m"),
    "map levels text": (lambda: sblsim.accuracy_map("semicircle", levels="0.5"), "levels: expected a list"),
    "compare receivers 5": (lambda: sblsim.compare("semicircle", receivers=5), "receivers: expected a text or a list"),
    "budget receiver list": (lambda: sblsim.budget("semicircle", receiver=["ekf"]), "receiver: ['ekf'] is not a text"),
    "replay None": (lambda: sblsim.replay(None), "log: None is not a file or folder"),
    "replay truth=1": (lambda: sblsim.replay("log.csv", truth=1), "truth: 1 is not a file or folder"),
    "replay config=1": (lambda: sblsim.replay("log.csv", config=1), "config: 1 is not a file or folder"),
    "campaign out None": (lambda: sblsim.campaign("paper", None), "out: None is not a file or folder"),
    "campaign resume 'yes'": (lambda: sblsim.campaign("paper", "c", resume="yes"), "resume: 'yes' is not True or"),
    "campaign workers 'two'": (lambda: sblsim.campaign("paper", "c", workers="two"), "workers: 'two' is not an"),
    "analyze None": (lambda: sblsim.analyze(None), "directory: None is not a file or folder"),
    "calibrate None": (lambda: sblsim.calibrate(None), "survey: None is not a file or folder"),
    "calibrate replicates '3'": (lambda: sblsim.calibrate("box-in", replicates="3"), "replicates: '3' is not an"),
    "calibrate out=1": (lambda: sblsim.calibrate("box-in", out=1), "out: 1 is not a file or folder"),
    "analyze alpha 'x'": (lambda: sblsim.analyze("c", alpha="x"), "alpha: 'x' is not a number"),
    # an array shown by its shape (its repr spans lines), numpy's bool refused as a bool is
    "run set array": (lambda: sblsim.run("semicircle", set={"platform.baseline": np.array([1.0, 2.0])}),
                      "set: platform.baseline: a numpy array of shape (2,) is not a number, text, boolean or list"),
    "load set 2-D array": (lambda: sblsim.load("semicircle", set={"platform.baseline": np.ones((2, 3))}),
                           "set: platform.baseline: a numpy array of shape (2, 3) is not a number"),
    "load configuration array": (lambda: sblsim.load({**sblsim.load("semicircle"), "platform": {
        **sblsim.load("semicircle")["platform"], "baseline": np.arange(40.0)}}),
        "platform.baseline: expected a number in (0, 1000] m, got a numpy array of shape (40,)"),
    "calibrate replicates numpy bool": (lambda: sblsim.calibrate("box-in", replicates=np.True_),
                                        "replicates: np.True_ is not an integer or None"),
    "run replicates numpy 0": (lambda: sblsim.run("semicircle", replicates=np.int64(0)),
                               "replicates: 0 is outside the allowed range [1, 100000] (an integer)"),
    "load seed numpy -1": (lambda: sblsim.load("semicircle", seed=np.int32(-1)),
                           "seed: -1 is outside the allowed range [0, 2147483647]"),
}


@pytest.mark.parametrize("case", list(HOSTILE))
def test_hostile_arguments_raise_the_documented_error_naming_the_argument(case, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    call, needle = HOSTILE[case]
    with pytest.raises(sblsim.SblsimError) as caught:
        call()
    message = str(caught.value)
    assert message.startswith(needle) and "\n" not in message, message
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_what_the_docstrings_allow_is_accepted():
    """accuracy_map's extent (0, 100000] m with a step of the extent; compare() of a Config (a mapping or Config,
    its docstring says), the same table as its scenario's."""
    m = sblsim.accuracy_map("semicircle", extent=50_000.0, step=50_000.0)
    assert list(m.east) == [-50_000.0, 0.0, 50_000.0] and m.maps[0].shape == (3, 3)
    assert np.all(m.maps[0] > 0) and m.maps[0][1, 1] < m.maps[0][0, 0]  # better under the platform than 50 km off
    cfg = sblsim.load("semicircle", set=[SHORT])
    mine = sblsim.compare(cfg, receivers=["ekf", "lsq"], replicates=2)
    theirs = sblsim.compare("semicircle", receivers=["ekf", "lsq"], replicates=2, set=[SHORT])
    keep = [k for k in theirs.table.columns if k != "us_per_step"]
    pd.testing.assert_frame_equal(mine.table[keep].reset_index(drop=True), theirs.table[keep].reset_index(drop=True))
    assert mine.title.startswith("semicircle: 2 replicates per receiver, seed 0")


def test_numpy_integers_are_accepted_where_integers_are():
    """A numpy integer scalar is an integer argument (a seed, a count) and a set value, as a Python integer is, with
    the same result; a bool (Python's or numpy's) is not one."""
    from sblsim.orchestrator.io.arguments import check_count, check_integer, check_seed

    assert sblsim.load("semicircle", seed=np.int64(7)) == sblsim.load("semicircle", seed=7)
    assert type(sblsim.load("semicircle", seed=np.uint16(7))["run"]["seed"]) is int
    assert sblsim.load("semicircle", set={"platform.gps_tau": np.int64(30), "platform.baseline": np.float32(0.5)}) \
        == sblsim.load("semicircle", set={"platform.gps_tau": 30, "platform.baseline": 0.5})
    for check in (lambda v: check_count(v, "n", 1, 9), lambda v: check_integer(v, "n"), check_seed):
        assert [type(check(v)) for v in (np.int8(3), np.uint64(3), 3)] == [int, int, int]
        for flag in (True, np.True_):
            with pytest.raises(sblsim.ConfigError):
                check(flag)
    short = {"survey.duration_s": 60.0}
    mine = sblsim.calibrate("box-in", replicates=np.int64(2), set=short).replicates
    pd.testing.assert_frame_equal(mine, sblsim.calibrate("box-in", replicates=2, set=short).replicates)


@pytest.mark.slow
def test_compare_map_and_budget_give_the_cli_tables(tmp_path):
    items = [SHORT]
    assert main(["compare", "semicircle", "--receivers", "ekf,lsq", "--replicates", "3", "--seed", "4",
                 "--set", SHORT, "--out", str(tmp_path / "c")]) == 0
    c = sblsim.compare("semicircle", receivers=["ekf", "lsq"], replicates=3, seed=4, set=items)
    cli = pd.read_csv(tmp_path / "c" / "compare.csv")
    keep = [k for k in cli.columns if k != "us_per_step"]  # a timing, not a result
    pd.testing.assert_frame_equal(c.table[keep].reset_index(drop=True), cli[keep], check_exact=False, rtol=1e-15)
    assert c.title in (tmp_path / "c" / "compare.md").read_text()

    assert main(["map", "semicircle", "--compare", "platform.baseline=0.5,2", "--step", "2", "--out",
                 str(tmp_path / "m")]) == 0
    m = sblsim.accuracy_map("semicircle", compare=("platform.baseline", [0.5, 2]), step=2.0)
    cli = pd.read_csv(tmp_path / "m" / "map.csv")
    assert np.array_equal(m.table["drms"].to_numpy(), cli["drms"].to_numpy(), equal_nan=True)
    assert len(m.maps) == 2 and m.maps[0].shape == (len(m.north), len(m.east))

    assert main(["budget", "semicircle", "--replicates", "3", "--set", SHORT, "--out", str(tmp_path / "b")]) == 0
    b = sblsim.budget("semicircle", replicates=3, set=items)
    cli = pd.read_csv(tmp_path / "b" / "budget.csv")
    assert np.allclose(b.table["contribution"].to_numpy(), cli["contribution"].to_numpy(), rtol=1e-12, atol=0)
    assert list(b.table["source"]) == list(cli["source"])


@pytest.mark.slow
def test_campaign_and_analyze_give_the_cli_results(tmp_path):
    import tomli_w

    study = {"study": {"name": "tiny", "scenarios": ["semicircle"], "replicates": 2, "seed": 3,
                       "set": ["simulation.duration=10"]},
             "factors": [{"name": "baseline", "key": "platform.baseline", "low": 0.5, "high": 2.0},
                         {"name": "range", "key": "acoustics.sigma_range", "low": 0.05, "high": 0.2}]}
    path = tmp_path / "tiny.toml"
    path.write_text(tomli_w.dumps(study))
    assert main(["campaign", str(path), "--workers", "1", "--out", str(tmp_path / "cli"), "--analyze"]) == 0
    seen = []
    result = sblsim.campaign(path, tmp_path / "api", workers=1, progress=lambda done, total: seen.append(done))
    assert seen[-1] == result.total == 8
    cli = pd.read_parquet(tmp_path / "cli" / "runs.parquet")
    pd.testing.assert_frame_equal(result.runs.drop(columns=["wall_time"], errors="ignore"),
                                  cli.drop(columns=["wall_time"], errors="ignore"))
    a = sblsim.analyze(tmp_path / "api")
    effects = pd.read_csv(tmp_path / "cli" / "effects.csv")
    assert np.allclose(a.effects["effect"].to_numpy(), effects["effect"].to_numpy(), rtol=1e-12, atol=1e-15)
    assert set(a.plot()) == {"pareto", "main_effects", "interactions", "residuals"}


@pytest.mark.slow
@pytest.mark.parametrize("survey, options", [("box-in", ["--replicates", "3"]), ("xie-2021-07-23", [])])
def test_calibrate_is_the_cli_calibration(tmp_path, survey, options):
    """A simulated survey with replicates and a recorded one: the same solution, tables and files."""
    assert main(["calibrate", survey, *options, "--out", str(tmp_path / "cli")]) == 0
    replicates = int(options[1]) if options else None
    result = sblsim.calibrate(survey, replicates=replicates, out=tmp_path / "api")
    cli = json.loads((tmp_path / "cli" / "solution.json").read_text())
    assert result.solution == cli == json.loads((tmp_path / "api" / "solution.json").read_text())
    for name in ("residuals.csv", "running.csv"):  # the tables the API holds are the files, byte for byte
        if (tmp_path / "cli" / name).exists():
            table = result.residuals if name == "residuals.csv" else result.running
            assert table.to_csv(index=False) == (tmp_path / "cli" / name).read_text() == (
                tmp_path / "api" / name).read_text()
    if replicates:
        assert len(result.replicates) == replicates == cli["replicates"]["count"]
        pd.testing.assert_frame_equal(result.replicates, pd.read_parquet(tmp_path / "cli" / "replicates.parquet"))
    else:
        assert result.replicates is None and result.segments == 4
    assert sorted(p.name for p in (tmp_path / "api").iterdir()) == sorted(p.name for p in (tmp_path / "cli").iterdir())
    quiet = sblsim.calibrate(survey, replicates=replicates)  # nothing written without out
    assert quiet.out is None and quiet.solution == cli


def test_every_public_name_exists_and_importing_sblsim_is_cheap():
    assert all(hasattr(sblsim, name) for name in sblsim.__all__)
    for name in ("load", "run", "compare", "accuracy_map", "budget", "replay", "calibrate", "campaign", "analyze"):
        assert callable(getattr(sblsim, name)) and getattr(sblsim, name).__doc__
    probe = ("import sys, sblsim; "
             "print(sorted(m for m in ('numpy', 'pandas', 'casadi', 'matplotlib') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=True)
    assert done.stdout.strip() == "[]"


def _cli_number(tmp_path: Path) -> float:
    done = subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", "run", "semicircle", "--seed", "1",
                           "--out", str(tmp_path / "cli")], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads((tmp_path / "cli" / "summary.json").read_text())["e_tot_rms"]


@pytest.mark.slow
def test_the_one_line_example_prints_the_cli_number(tmp_path):
    line = "import sblsim; r = sblsim.run('semicircle', seed=1); print(r.summary['e_tot_rms'])"
    done = subprocess.run([sys.executable, "-c", line], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert float(done.stdout) == _cli_number(tmp_path)
    assert list(p.name for p in tmp_path.iterdir()) == ["cli"]  # the API wrote nothing


NOTEBOOK = textwrap.dedent("""
    import sblsim

    cfg = sblsim.load("semicircle", seed=1)
    result = sblsim.run(cfg)
    table = result.timeseries
    rms = float((table["e_tot"] ** 2).mean() ** 0.5)
    figures = result.plot()
    print(repr(result.summary["e_tot_rms"]), repr(rms), len(figures))
""")


@pytest.mark.slow
def test_a_notebook_script_of_public_names_reproduces_the_cli_result(tmp_path):
    tree = ast.parse(NOTEBOOK)
    used = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name)
            and n.value.id == "sblsim"}
    assert used and used <= set(sblsim.__all__)
    done = subprocess.run([sys.executable, "-c", NOTEBOOK], cwd=tmp_path, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    summary, mine, count = done.stdout.split()
    cli = _cli_number(tmp_path)
    assert float(summary) == cli and int(count) == 4
    assert float(mine) == pytest.approx(cli, rel=1e-12)  # the RMS of the time series' e_tot is the summary's
