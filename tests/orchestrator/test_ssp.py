"""SSP export and read-back: schema validation, the scenario's connections and parameters, round trip."""

from __future__ import annotations

import re
import zipfile
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.ssp.ssd import read_ssd, read_ssv

from sblsim.models import MODELS
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.connections import default_connections
from sblsim.orchestrator.cosim.plan import make_plan
from sblsim.orchestrator.cosim.run import run
from sblsim.orchestrator.cosim.ssp import SspError, export_ssp, validate_ssp
from sblsim.orchestrator.cosim.ssp_read import read_ssp


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
    """One system-wide set (every .ssv has the system's name), numbers only (no String: OMSimulator cannot
    set one), each value the FMU value of the configuration (choices as their index)."""
    cfg, path = exported
    system = read_ssd(str(path)).system
    names = set()
    for comp in system.elements:
        (binding,) = comp.parameterBindings
        assert binding.type == "application/x-ssp-parameter-set"
        pset = read_ssv(str(path), resource=binding.source)  # read again, on its own, validated
        names.add(pset.name)
        got = {p.name: p for p in pset.parameters}
        model = MODELS[comp.name]
        want = model.fmi_values(make_plan(cfg).component_parameters(comp.name))
        assert set(got) == set(want)
        for name, value in want.items():
            p = got[name]
            assert p.type in ("Real", "Integer", "Boolean")
            if p.type == "Real":
                assert float(p.value) == float(value)
            elif p.type == "Integer":
                assert int(p.value) == value
            else:
                assert p.value == ("true" if value else "false")
    assert names == {system.name} == {"semicircle"}
    assert {p.name: p.value for p in read_ssv(str(path), resource="resources/acoustics.ssv").parameters}[
        "loss_pct"] == "10.0"
    target = {p.name: p.value for p in read_ssv(str(path), resource="resources/target.ssv").parameters}
    assert target["trajectory"] == str(["semicircle", "spiral", "random", "square", "file"].index("semicircle"))


def test_names_annotations_and_default_experiment_suit_every_host(exported):
    """Identifiers as names, the base step where OMSimulator and libcosim read it, no component annotation."""
    cfg, path = exported
    with zipfile.ZipFile(path) as archive:
        text = archive.read("SystemStructure.ssd").decode()
    root = ET.fromstring(text)
    ns = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription"}
    ident = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
    assert ident.match(root.get("name")) and ident.match(root.find("ssd:System", ns).get("name"))
    assert all(ident.match(c.get("name")) for c in root.findall(".//ssd:Component", ns))
    assert all(c.find("ssd:Annotations", ns) is None for c in root.findall(".//ssd:Component", ns))
    assert "StepSizeHint" not in text
    assert '<ssd:DefaultExperiment startTime="0.0" stopTime="20.0">' in text
    assert '<osp:FixedStepAlgorithm baseStepSize="0.1" />' in text
    assert 'type="org.openmodelica"' in text and '<oms:FixedStepMaster description="oms-ma" stepSize="0.1"' in text


def test_multi_rate_package_steps_every_component_at_the_receivers_step(fmu_dir, tmp_path):
    cfg = load_config("semicircle", ["simulation.duration=2", "simulation.ekf_rate_ratio=4"])
    path = export_ssp(cfg, tmp_path / "m.ssp", fmu_dir)
    with zipfile.ZipFile(path) as archive:
        text = archive.read("SystemStructure.ssd").decode()
    assert '<osp:FixedStepAlgorithm baseStepSize="0.025" />' in text and 'stepSize="0.025"' in text
    back = read_ssp(path).config["simulation"]
    assert (back["ekf_rate_ratio"], back["sampling_time"]) == (4, 0.1)  # T from the channel's slot period


def test_a_scenario_name_that_is_not_an_identifier_is_made_one(fmu_dir, tmp_path):
    cfg = load_config("semicircle", ["simulation.duration=1", "run.scenario=my semicircle 2"])
    path = export_ssp(cfg, tmp_path / "n.ssp", fmu_dir)
    system = read_ssd(str(path)).system
    assert system.name == "my_semicircle_2"


def test_tables_travel_in_the_package_as_numbers(fmu_dir, tmp_path):
    """The harbour's CTD cast and a file trajectory are parameter arrays in the set, and come back."""
    track = tmp_path / "track.csv"
    track.write_text("time,N,E,D\n0,0,0,2\n20,10,0,2.5\n40,10,10,3\n")
    cfg = load_config("harbour", ["simulation.duration=5", "target.trajectory=file",
                                  f"target.trajectory_file={track}"])
    path = export_ssp(cfg, tmp_path / "h.ssp", fmu_dir)
    acoustics = {p.name: p.value for p in read_ssv(str(path), resource="resources/acoustics.ssv").parameters}
    rows = int(acoustics["sound_speed_rows"])
    assert rows > 50 and float(acoustics["sound_speed[1]"]) == pytest.approx(1512.6, abs=0.1)
    back = read_ssp(path).config
    assert back["acoustics"]["sound_speed_profile"] == "table"
    assert back["target"]["trajectory"] == "file" and back["target"]["trajectory_file"] == ""
    a, b = run(cfg), run(back)
    np.testing.assert_array_equal(a.timeseries["est_x"], b.timeseries["est_x"])


def test_read_back_gives_the_same_configuration_and_connections(exported):
    cfg, path = exported
    system = read_ssp(path)
    assert system.config == cfg
    assert system.connections == default_connections(4)
    assert set(system.fmu_files) == {"platform", "acoustics", "target", "receiver"}
    assert all(p.is_file() for p in system.fmu_files.values())
    again = read_ssp(path, ["master=jacobi"], seed=9)
    assert again.config["simulation"]["master"] == "jacobi" and again.config["run"]["seed"] == 9


@pytest.mark.slow
def test_run_ssp_on_the_local_engine_equals_run_of_the_scenario(exported, tmp_path, capsys):
    cfg, path = exported
    assert main(["run", "--ssp", str(path), "--engine", "local", "--out", str(tmp_path / "r")]) == 0
    import pandas as pd

    got = pd.read_parquet(tmp_path / "r" / "timeseries.parquet")
    want = run(cfg).timeseries
    assert np.array_equal(got["est_x"], want["est_x"], equal_nan=True)  # NaN before the first fix
    assert np.array_equal(got["e_tot"], want["e_tot"], equal_nan=True)


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
