"""The water a study's user knows (issue 87, item 5) in ``sblsim track``: ``--temperature-file`` (the sound speed by
TEOS-10 at ``--salinity``) and ``--water-depth`` reach every tag's tracker as they reach ``sblsim replay``'s, and a
deployments table's ``bottom_depth`` gives each tag's water depth where no ``--water-depth`` is given (the deepest of
the deployments that heard it), said in the console and the summary; ``bottom_depth`` read and checked (a negative
or non-numeric cell, or a bottom above its instrument, refused in one line naming the line and the column).

The study is simulated with clocks that keep UTC and no sync tag in the deployments (the clocks taken as logged:
no synchronisation to wait for), its receivers given one depth (5 m: in one plane, so the tag's depth is held at
mid-water where the water's depth is known, :func:`sblsim.models.tracking.depth.plane_prior`)."""

from __future__ import annotations

import json

import gsw
import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.io.times import iso_utc
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.receivers_file import read_receivers
from sblsim.orchestrator.readers.toa_matrix import read_toa
from sblsim.orchestrator.telemetry.simulate import simulate_study
from tests.helpers import check_tag_rows

#: The receivers' depth [m] and each one's bottom [m] (20, 22, ... m).
INSTRUMENT = 5.0
TEMPERATURE, SALINITY = 12.0, 0.0


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """A 1.2-hour study of 8 receivers and one sbi tag, its deployments with ``instrument_depth`` and
    ``bottom_depth`` and without sync tags; a temperature series in UTC over it."""
    folder = tmp_path_factory.mktemp("water")
    sim = simulate_study(n_receivers=8, n_tags=1, days=0.05, redeployed=0, seed=5, offset=0.0, drift=0.0)
    files = sim.write(folder / "files", "vue")
    table = pd.read_csv(files["deployments"], dtype=str).drop(columns="transmitter")
    table["instrument_depth"] = INSTRUMENT
    table["bottom_depth"] = 20.0 + 2.0 * np.arange(len(table))
    table.to_csv(files["deployments"], index=False)
    times = sim.origin + np.array([-3600.0, 0.2 * 86400.0])
    pd.DataFrame({"time_utc": iso_utc(times), "temperature_c": TEMPERATURE}).to_csv(folder / "temperature.csv",
                                                                                    index=False)
    tag = sim.sheet.loc[sim.sheet["role"] == "animal", "transmitter"].iloc[0]
    return files, folder, tag, table


def _tag_summary(out, result) -> dict:
    folder = result.tags["folder"].iloc[0]
    return json.loads((out / folder / "summary.json").read_text())


@pytest.mark.slow
def test_water_depth_and_temperature_file_reach_the_tracker(study, capsys):
    """``sblsim track --water-depth 30 --temperature-file CSV --salinity 0``: the tag's depth held at mid-water,
    15 ± 30/√12 m (a uniform over the column), and its sound speed TEOS-10's at 12 °C in fresh water (gsw here,
    at the surface and at the bottom: the speed lies between); the console says both."""
    files, folder, tag, _ = study
    out = folder / "given"
    assert main(["track", str(files["detections"]), "--receivers", str(files["deployments"]), "--tag", tag,
                 "--water-depth", "30", "--temperature-file", str(folder / "temperature.csv"), "--salinity",
                 str(SALINITY), "--workers", "1", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "water depth 30 m (given, --water-depth)" in printed
    tags = pd.read_csv(out / "tags.csv", dtype=str)
    check_tag_rows(pd.read_csv(out / "tags.csv", dtype={"tag": str}), pd.read_csv(out / "tracks.csv",
                                                                                   dtype={"tag": str}))
    assert tags["status"].tolist() == ["tracked"]
    summary = json.loads((out / tags["folder"].iloc[0] / "summary.json").read_text())
    depth = summary["depth"]
    assert depth["water_depth_m"] == 30.0 and depth["basis"] == "plane"
    assert depth["depth_m"] == pytest.approx(15.0) and depth["sigma_m"] == pytest.approx(30.0 / np.sqrt(12.0))
    sr = gsw.SR_from_SP(SALINITY)
    bounds = [gsw.sound_speed(sr, gsw.CT_from_t(sr, TEMPERATURE, p), p) for p in (0.0, gsw.p_from_z(-30.0, 60.38))]
    speed = summary["sound_speed"]
    assert "temperature" in speed["source"]
    assert min(bounds) - 0.01 <= speed["sound_speed_m_s"] <= max(bounds) + 0.01, (speed, bounds)
    study_json = json.loads((out / "study.json").read_text())
    assert study_json["water_depth"] == {"source": "given", "water_depth_m": 30.0}


@pytest.mark.slow
def test_each_tag_takes_the_deepest_bottom_of_its_receivers(study):
    """Without ``--water-depth``, the tag's water depth is the deepest ``bottom_depth`` of the deployments whose
    column of its matrix holds an arrival (found here from its ``toa.txt``), its depth held at half of it; the
    summary says the rule and the depth."""
    files, folder, tag, table = study
    out = folder / "bottom"
    result = sblsim.track(files["detections"], receivers=files["deployments"], tag=tag, workers=1, out=out)
    check_tag_rows(result.tags, result.tracks)
    assert result.tags["status"].tolist() == ["tracked"]
    where = out / result.tags["folder"].iloc[0]
    names = read_receivers(where / "receivers.csv").names
    heard = [n for n, ok in zip(names, np.isfinite(read_toa(where / "toa.txt").toa).any(axis=0)) if ok]
    bottom = table.set_index("ins_serial_no")["bottom_depth"]
    expected = float(bottom[heard].max())
    assert expected < float(bottom.max()) or len(heard) == len(bottom)
    water = result.summary["water_depth"]
    assert water["source"] == "bottom_depth" and "deepest" in water["rule"]
    assert water["per_tag_m"] == {result.tags["tag"].iloc[0]: expected}
    depth = _tag_summary(out, result)["depth"]
    assert depth["water_depth_m"] == expected and depth["depth_m"] == pytest.approx(expected / 2)


def test_bad_water_options_are_refused_in_one_line(study, tmp_path, capsys):
    """A water depth above the receivers, a temperature file on no stated time base, and a water depth where the
    deployments give no depths are each refused in one line, exit 2, nothing written."""
    files, folder, tag, table = study
    relative = tmp_path / "relative.csv"
    pd.DataFrame({"time_s": [0.0, 9000.0], "temperature_c": 10.0}).to_csv(relative, index=False)
    flat = tmp_path / "flat.csv"
    table.drop(columns=["instrument_depth", "bottom_depth"]).to_csv(flat, index=False)
    for extra, receivers, found in ((["--water-depth", "3"], files["deployments"], "water_depth: 3 m is above"),
                                    (["--temperature-file", str(relative), "--salinity", "0"], files["deployments"],
                                     "times on no stated base"),
                                    (["--water-depth", "30"], flat, "needs the receivers' depths")):
        code = main(["track", str(files["detections"]), "--receivers", str(receivers), "--tag", tag, *extra,
                     "--out", str(tmp_path / "out")])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and found in err[0], err
        assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("cell, found", [("-4", "line 3 column bottom_depth: '-4'"),
                                         ("deep", "line 3 column bottom_depth: 'deep'"),
                                         ("3", "line 3 column bottom_depth: 3 m is above the instrument at 5 m")])
def test_bottom_depth_read_and_checked(tmp_path, cell, found):
    """``bottom_depth`` read per deployment (empty: NaN); a negative or non-numeric cell, or a bottom above its
    instrument, refused in one line naming the line and the column."""
    rows = pd.DataFrame({"serial": ["A", "B", "C"], "x_m": [0.0, 100.0, 0.0], "y_m": [0.0, 0.0, 100.0],
                         "instrument_depth": [5.0, 5.0, 5.0], "bottom_depth": ["12.5", "", "30"]})
    rows.to_csv(tmp_path / "ok.csv", index=False)
    read = read_deployments(tmp_path / "ok.csv").table
    np.testing.assert_array_equal(read["bottom_depth"], [12.5, np.nan, 30.0])
    rows.loc[1, "bottom_depth"] = cell
    rows.to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(ModelError) as error:
        read_deployments(tmp_path / "bad.csv")
    assert found in str(error.value) and "\n" not in str(error.value), str(error.value)
