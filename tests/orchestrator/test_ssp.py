"""SSP export and read-back: schema validation, the scenario's connections and parameters, round trip."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.ssp.ssd import read_ssd, read_ssv

from orchestrator.cli import main
from orchestrator.config import component_params, load_config
from orchestrator.connections import default_connections
from orchestrator.run import run
from orchestrator.ssp import SspError, export_ssp, read_ssp, validate_ssp


@pytest.fixture(scope="module")
def exported(fmu_dir, tmp_path_factory):
    cfg = load_config("semicircle", ["simulation.duration=20", "acoustics.loss_pct=10"], seed=5)
    path = export_ssp(cfg, tmp_path_factory.mktemp("ssp") / "semicircle.ssp", fmu_dir)
    return cfg, path


def test_package_validates_against_the_ssp_schemas_and_a_broken_one_does_not(exported, tmp_path):
    cfg, path = exported
    ssd = read_ssd(str(path), validate=True)  # fmpy validates the .ssd and every bound .ssv
    assert ssd.version == "1.0"
    broken = tmp_path / "broken.ssp"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(broken, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item == "SystemStructure.ssd":
                data = data.replace(b'kind="output"', b'kind="sideways"', 1)
            dst.writestr(item, data)
    with pytest.raises(SspError, match="not a valid SSP 1.0 package"):
        validate_ssp(broken)


def test_connections_in_the_ssd_equal_the_scenarios(exported):
    cfg, path = exported
    system = read_ssd(str(path)).system
    got = {(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in system.connections}
    want = {(c.source, c.output, c.destination, c.input) for c in default_connections(4)}
    assert got == want and len(system.connections) == len(want)


def test_components_connectors_units_and_fmus(exported, fmu_dir):
    cfg, path = exported
    system = read_ssd(str(path)).system
    assert [c.name for c in system.elements] == ["platform", "acoustics", "target", "receiver"]
    with zipfile.ZipFile(path) as archive:
        names = set(archive.namelist())
        for comp in system.elements:
            assert comp.source in names
            md = read_model_description(str(fmu_dir / f"sblsim_{comp.name}.fmu"))
            signals = {v.name: v for v in md.modelVariables if v.causality in ("input", "output")}
            assert {c.name for c in comp.connectors} == set(signals)
            assert all(c.kind == signals[c.name].causality for c in comp.connectors)
            assert archive.read(comp.source) == (fmu_dir / f"sblsim_{comp.name}.fmu").read_bytes()
        ssd_text = archive.read("SystemStructure.ssd").decode()
    # every Real connector carries its FMU unit
    for comp in system.elements:
        md = read_model_description(str(fmu_dir / f"sblsim_{comp.name}.fmu"))
        for v in md.modelVariables:
            if v.causality in ("input", "output") and v.type == "Real":
                assert f'<ssd:Connector name="{v.name}" kind="{v.causality}">\n            <ssc:Real unit="{v.unit}"' \
                    in ssd_text


def test_parameter_sets_hold_the_scenarios_values(exported):
    cfg, path = exported
    system = read_ssd(str(path)).system
    for comp in system.elements:
        (binding,) = comp.parameterBindings
        pset = read_ssv(str(path), resource=binding.source)  # read again, on its own, validated
        got = {p.name: p for p in pset.parameters}
        want = component_params(cfg, comp.name)
        assert set(got) == set(want)
        for name, value in want.items():
            p = got[name]
            if p.type == "Real":
                assert float(p.value) == float(value)
            elif p.type == "Integer":
                assert int(p.value) == value
            elif p.type == "Boolean":
                assert p.value == ("true" if value else "false")
            else:
                assert p.value == value
    assert {p.name: p.value for p in read_ssv(str(path), resource="resources/acoustics.ssv").parameters}[
        "loss_pct"] == "10.0"


def test_default_experiment_and_step_hints(exported):
    cfg, path = exported
    with zipfile.ZipFile(path) as archive:
        text = archive.read("SystemStructure.ssd").decode()
    assert '<ssd:DefaultExperiment startTime="0.0" stopTime="20.0">' in text
    assert '<osp:FixedStepAlgorithm baseStepSize="0.1" />' in text
    assert text.count('<osp:StepSizeHint value="0.1" />') == 4


def test_multi_rate_package_gives_the_receiver_its_own_step(fmu_dir, tmp_path):
    cfg = load_config("semicircle", ["simulation.duration=2", "simulation.ekf_rate_ratio=4"])
    path = export_ssp(cfg, tmp_path / "m.ssp", fmu_dir)
    with zipfile.ZipFile(path) as archive:
        text = archive.read("SystemStructure.ssd").decode()
    assert '<osp:FixedStepAlgorithm baseStepSize="0.025" />' in text
    assert text.count('<osp:StepSizeHint value="0.1" />') == 3 and '<osp:StepSizeHint value="0.025" />' in text
    assert read_ssp(path).config["simulation"]["ekf_rate_ratio"] == 4


def test_read_back_gives_the_same_configuration_and_connections(exported):
    cfg, path = exported
    system = read_ssp(path)
    assert system.config == cfg
    assert system.connections == default_connections(4)
    assert set(system.fmu_files) == {"platform", "acoustics", "target", "receiver"}
    assert all(p.is_file() for p in system.fmu_files.values())
    again = read_ssp(path, ["master=jacobi"], seed=9)
    assert again.config["simulation"]["master"] == "jacobi" and again.config["run"]["seed"] == 9


def test_run_ssp_on_the_local_engine_equals_run_of_the_scenario(exported, tmp_path, capsys):
    cfg, path = exported
    assert main(["run", "--ssp", str(path), "--engine", "local", "--out", str(tmp_path / "r")]) == 0
    import pandas as pd

    got = pd.read_parquet(tmp_path / "r" / "timeseries.parquet")
    want = run(cfg).timeseries
    assert np.array_equal(got["est_x"], want["est_x"]) and np.array_equal(got["e_tot"], want["e_tot"])


def test_an_edited_connection_reaches_the_master(exported, tmp_path):
    cfg, path = exported
    edited = tmp_path / "edited.ssp"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(edited, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item == "SystemStructure.ssd":  # feed the channel the broadcast (GPS) positions as the truth
                for axis in "xyz":
                    data = data.replace(f'startConnector="beacon1_true_{axis}"'.encode(),
                                        f'startConnector="beacon1_{axis}"'.encode())
            dst.writestr(item, data)
    system = read_ssp(edited)
    changed = [c for c in system.connections if c.output == c.input.replace("_true", "") != c.input]
    assert sorted(c.input for c in changed) == ["beacon1_true_x", "beacon1_true_y", "beacon1_true_z"]
    a = run(system.config, connections=system.connections).timeseries
    b = run(cfg).timeseries
    assert not np.allclose(a["range_true"], b["range_true"], equal_nan=True)


def test_bad_export_and_read_input(fmu_dir, tmp_path, capsys):
    assert main(["ssp", "export", "semicircle", "--out", str(tmp_path / "x.zip"), "--fmu-dir", str(fmu_dir)]) == 2
    assert "must end in .ssp" in capsys.readouterr().err
    assert main(["ssp", "export", "semicircle", "--out", str(tmp_path / "x.ssp"), "--fmu-dir",
                 str(tmp_path / "none")]) == 2
    assert "FMU not found" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.ssp*"))
    assert main(["run", "--ssp", str(tmp_path / "missing.ssp")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["run", "semicircle", "--ssp", str(tmp_path / "missing.ssp")]) == 2
    assert "either a scenario" in capsys.readouterr().err
