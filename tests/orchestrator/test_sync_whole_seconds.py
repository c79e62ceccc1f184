"""``sblsim sync`` on times rounded to whole seconds and on receivers tables in another unit (issue 97 item 4, issue 98
items 4 and 8): refused in one line with exit status 2 before the clocks are fitted, the rounding named as the cause
(not the positions), never a traceback; a finer rounding said against the synchronisation's own residuals. On a
small simulated array written as YAPS tables, the rounding and the factors applied here."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.errors import ModelError
from sblsim.models.sync.simulate import simulate_sync
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.sync import run
from sblsim.orchestrator.sync.declared import check_arrival_spread

#: The simulated files' epoch [s since 1970 UTC].
EPOCH = 1_700_000_000
#: A number in a message.
NUMBER = r"(-?[0-9.]+(?:e[+-]?[0-9]+)?)"


@pytest.fixture(scope="module")
def sim():
    """Six receivers over 600 m with their sync tags, 3 h at 200-300 s intervals, 0.15 ms of noise."""
    return simulate_sync(n_receivers=6, hours=3.0, seed=5, side=600.0, interval=(200.0, 300.0), noise=0.15e-3)


def _files(folder: Path, sim, quantum: float = 0.0, factor: float = 1.0, degrees: bool = False,
           sync_tags: int | None = None) -> tuple[Path, Path]:
    """The simulation as a YAPS table (times rounded to ``quantum`` [s], 0: to 0.1 µs) and a receivers table (the
    positions times ``factor``, or as longitudes and latitudes near 60.4° N under x_m, y_m; the first ``sync_tags``
    receivers' sync tags only)."""
    folder.mkdir(exist_ok=True)
    t = sim.time + EPOCH
    if quantum:
        t = np.round(t / quantum) * quantum
    epo = np.floor(t).astype(np.int64)
    table = pd.DataFrame({"epo": epo, "frac": [f"{v:.7f}" for v in np.clip(t - epo, 0, 0.9999999)],
                          "tag": [f"S{i}" for i in sim.tag], "serial": [f"R{j}" for j in sim.receiver]})
    detections = folder / "detections.csv"
    table.iloc[np.lexsort((table["frac"].astype(float), table["epo"]))].to_csv(detections, index=False)
    x, y = sim.positions[:, 0] * factor, sim.positions[:, 1] * factor
    if degrees:
        x, y = 5.34 + sim.positions[:, 0] / 55_100.0, 60.38 + sim.positions[:, 1] / 111_300.0
    n = len(sim.positions)
    tags = [f"S{j}" if sync_tags is None or j < sync_tags else "" for j in range(n)]
    receivers = folder / "receivers.csv"
    pd.DataFrame({"serial": [f"R{j}" for j in range(n)], "sync_tag": tags, "x_m": x, "y_m": y}).to_csv(receivers,
                                                                                                      index=False)
    return detections, receivers


def _refused(capsys, detections: Path, receivers: Path, out: Path, *extra: str) -> str:
    code = main(["sync", str(detections), "--receivers", str(receivers), "--out", str(out), *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and not out.exists(), (code, err)
    assert err[0].startswith("sblsim: error: ")
    return err[0]


@pytest.fixture
def no_fit(monkeypatch):
    """The clocks' fit made to fail: a refusal that reaches the line came before the work."""
    def fit(*args, **kwargs):
        raise AssertionError("the clocks were fitted")
    monkeypatch.setattr(run, "fit_with_breaks", fit)


@pytest.mark.parametrize("extra, sync_tags", [((), None), (("--refine-positions",), None), ((), 1)])
def test_whole_seconds_are_refused_before_the_work_naming_the_rounding(sim, tmp_path, capsys, no_fit, extra,
                                                                       sync_tags):
    """The detections rounded to whole seconds (the boats' with ``frac`` 0 were refused as 'not metres' after 30 s
    of work; with the positions refined or one sync tag, a traceback): exit 2, one line naming the file, whole
    seconds as the cause and the rounding's σ (1/√12 s = 289 ms), with the positions refined and with one sync tag
    (no double difference to weigh the table by) alike, the clocks never fitted."""
    detections, receivers = _files(tmp_path / "in", sim, quantum=1.0, sync_tags=sync_tags)
    line = _refused(capsys, detections, receivers, tmp_path / "out", *extra)
    assert "detections.csv': every time is a whole multiple of 1 s (whole seconds" in line, line
    assert f"a rounding error of {1000 / np.sqrt(12):.3g} ms" in line and "not the receivers' positions" in line


def test_the_python_function_refuses_them_too(sim, tmp_path):
    detections, receivers = _files(tmp_path / "in", sim, quantum=1.0)
    with pytest.raises(ModelError, match="whole seconds"):
        sblsim.sync(detections, receivers=receivers)


@pytest.mark.parametrize("sync_tags", [None, 1])
def test_degrees_under_metre_columns_exit_2_not_a_traceback(sim, tmp_path, capsys, no_fit, sync_tags):
    """Longitudes and latitudes under x_m, y_m (a traceback, exit status 1, before): exit 2, one line naming
    degrees, with every sync tag or one (then nothing to weigh by sound: the values alone)."""
    detections, receivers = _files(tmp_path / "in", sim, degrees=True, sync_tags=sync_tags)
    line = _refused(capsys, detections, receivers, tmp_path / "out")
    assert "receivers.csv'" in line and "look like degrees" in line, line


def test_toa_names_degrees_by_their_values():
    """``sblsim toa``'s check of one tag's arrivals: the boats' pings spread over 71 ms where a table of degrees
    under x_m, y_m makes the crossing 0.012 ms (a factor of 6,000, the spread a lower bound of the 10⁵): named
    degrees by the values (kilometres before); the same factor on a table in metres' values: kilometres."""
    lon, lat = np.array([5.335, 5.341, 5.350]), np.array([60.380, 60.384, 60.381])
    with pytest.raises(ModelError, match="look like degrees"):
        check_arrival_spread(np.full(5, 71e-3), 0.012e-3, 0.0, "r.csv", lon, lat)
    with pytest.raises(ModelError, match="look like kilometres"):
        check_arrival_spread(np.full(5, 71e-3), 0.012e-3, 0.0, "r.csv", lon * 1e3, lat * 1e3)


def test_feet_are_refused_naming_feet(sim, tmp_path, capsys, no_fit):
    """The positions times 3.2808 (feet; the factor-of-ten rule let them pass): exit 2 naming feet, the factor the
    line gives 1/3.2808 within 2 %."""
    detections, receivers = _files(tmp_path / "in", sim, factor=3.2808)
    line = _refused(capsys, detections, receivers, tmp_path / "out", "--sound-speed", f"{sim.sound_speed}")
    found = float(re.search(rf"put the receivers {NUMBER} times as far apart", line).group(1))
    assert "look like feet" in line and found == pytest.approx(1 / 3.2808, rel=0.02), line


@pytest.mark.slow
def test_tenths_are_said_against_the_sync_s_residuals(sim, tmp_path, capsys):
    """Tenths of a second on this array (σ 28.9 ms, below a tenth of its 0.57 s crossing: not refused) where the
    sync reaches 0.15 ms: exit 0 and one warning line naming tenths as what limits the clocks; every receiver has
    residuals (sync.json's robust scale) within √2 of the rounding's σ, as the rule says; the same times to 0.1 µs:
    no such line."""
    lines = {}
    for name, quantum in (("tenths", 0.1), ("fine", 0.0)):
        detections, receivers = _files(tmp_path / name, sim, quantum=quantum)
        out = tmp_path / name / "out"
        code = main(["sync", str(detections), "--receivers", str(receivers), "--out", str(out), "--sound-speed",
                     f"{sim.sound_speed}"])
        assert code == 0
        lines[name] = [x for x in capsys.readouterr().err.splitlines() if "whole multiples" in x]
    assert lines["fine"] == [] and len(lines["tenths"]) == 1, lines
    line = lines["tenths"][0]
    assert line.startswith("sblsim: warning: detections '") and "(tenths of a second" in line, line
    sigma = 0.1 / np.sqrt(12.0)
    noise = json.loads((tmp_path / "tenths" / "out" / "sync.json").read_text())["toa_noise"]
    assert "every receiver's times" in line and all(v["residuals_s"] <= np.sqrt(2) * sigma for v in noise.values())


def test_each_receiver_s_rounding_reaches_the_left_out_sync_tags_verdicts(sim, tmp_path, monkeypatch):
    """Hundredths of a second: every left-out sync tag's still-tag verdict is given each receiver's rounding σ
    (0.01 / √12 s: :func:`~sblsim.models.tracking.still_tag.still_tag`'s ``rounding``); the times to 0.1 µs: none."""
    from sblsim.orchestrator.sync import sync_tags

    given = []

    def still_tag(*args, rounding=None, **kwargs):
        given.append(None if rounding is None else np.asarray(rounding, float).copy())
        return real(*args, rounding=rounding, **kwargs)

    real = sync_tags.still_tag
    monkeypatch.setattr(sync_tags, "still_tag", still_tag)
    for name, quantum, expected in (("hundredths", 0.01, 0.01 / np.sqrt(12.0)), ("fine", 0.0, 0.0)):
        given.clear()
        detections, receivers = _files(tmp_path / name, sim, quantum=quantum)
        sblsim.sync(detections, receivers=receivers, out=tmp_path / name / "out", sound_speed=sim.sound_speed)
        assert len(given) == len(sim.positions), len(given)
        for rounding in given:
            np.testing.assert_allclose(rounding, np.full(len(sim.positions), expected), rtol=1e-9, atol=1e-12)


def test_a_tag_s_matrix_carries_its_times_rounding_to_a_still_tag_s_verdict(sim, tmp_path, monkeypatch):
    """``sblsim toa`` on hundredths writes each receiver's rounding σ (0.01 / √12 s) as ``receivers.csv``'s
    ``rounding_sigma_s``, the tracker reads it and hands it to a still tag's verdict
    (:func:`~sblsim.models.tracking.still_tag.still_tag`'s ``rounding``); the times to 0.1 µs write zeros; a value
    beyond the coarsest rounding's σ is refused naming the column."""
    from sblsim.orchestrator.readers.receivers_file import read_receivers
    from sblsim.orchestrator.tracks import track as tracking

    given = []

    def still_tag(*args, **kwargs):
        given.append(np.asarray(args[10], float).copy())
        return real(*args, **kwargs)

    real = tracking.still_tag
    monkeypatch.setattr(tracking, "still_tag", still_tag)
    for name, quantum, expected in (("hundredths", 0.01, 0.01 / np.sqrt(12.0)), ("fine", 0.0, 0.0)):
        detections, receivers = _files(tmp_path / name, sim, quantum=quantum)
        folder = tmp_path / name
        assert main(["sync", str(detections), "--receivers", str(receivers), "--out", str(folder / "sync")]) == 0
        assert main(["toa", str(detections), "--receivers", str(receivers), "--sync", str(folder / "sync"), "--tag",
                     "S1", "--out", str(folder / "toa")]) == 0
        table = pd.read_csv(folder / "toa" / "receivers.csv")
        np.testing.assert_allclose(table["rounding_sigma_s"], expected, rtol=1e-5, atol=1e-12)
        np.testing.assert_allclose(read_receivers(folder / "toa" / "receivers.csv").rounding, expected, rtol=1e-5,
                                   atol=1e-12)
        given.clear()
        tracking.track(folder / "toa" / "toa.txt", folder / "toa" / "receivers.csv", motion="stationary")
        assert len(given) == 1
        np.testing.assert_allclose(given[0], expected, rtol=1e-5, atol=1e-12)
    table["rounding_sigma_s"] = 30.0
    table.to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(ModelError, match="rounding_sigma_s"):
        read_receivers(tmp_path / "bad.csv")


def test_a_receiver_with_few_of_a_tag_s_times_takes_the_tag_s_rounding(sim, tmp_path):
    """Hundredths everywhere, but receiver R5 keeps three of tag S1's times, each a whole tenth (as three times of
    hundredths are, one time in a thousand): its ``rounding_sigma_s`` is the tag's (0.01 / √12 s), not a tenth's;
    every other receiver's its own."""
    from sblsim.orchestrator.sync.toa import FEW_TIMES

    detections, receivers = _files(tmp_path, sim, quantum=0.01)
    assert main(["sync", str(detections), "--receivers", str(receivers), "--out", str(tmp_path / "sync")]) == 0
    table = pd.read_csv(detections, dtype={"frac": str})
    at = np.flatnonzero(((table["tag"] == "S1") & (table["serial"] == "R5")).to_numpy())
    assert len(at) > FEW_TIMES
    table = table.drop(index=at[3:])
    frac = np.round(table.loc[at[:3], "frac"].astype(float).to_numpy(), 1)
    assert (frac < 1.0).all()
    table.loc[at[:3], "frac"] = [f"{v:.7f}" for v in frac]
    table.to_csv(detections, index=False)
    assert main(["toa", str(detections), "--receivers", str(receivers), "--sync", str(tmp_path / "sync"), "--tag",
                 "S1", "--out", str(tmp_path / "toa")]) == 0
    written = pd.read_csv(tmp_path / "toa" / "receivers.csv").set_index("name")["rounding_sigma_s"]
    np.testing.assert_allclose(written.to_numpy(), 0.01 / np.sqrt(12.0), rtol=1e-5)
