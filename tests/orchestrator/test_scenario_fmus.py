"""FMUs that carry their scenario (``sblsim fmus build --scenario``): a host that sets no parameter runs the site.

For the two site scenarios, ``lbl-field`` (LBL, two-way ranging, rays through a summer profile, SNR detection)
and ``usbl-deep`` (USBL on the real NCL1 cast):

* every parameter the ``.ssv`` files of ``sblsim ssp export`` bind is the scenario FMU's start value in its
  ``modelDescription.xml`` and the value the FMU reports after an initialization that set nothing;
* the project's plain C host (``tests/fmus_tests/c_host.c --system``), which sets no parameter, runs the
  four scenario FMUs connected as the package connects them with a Jacobi master, and every output it records
  equals ``sblsim run SCENARIO --engine fmu --master jacobi --seed N`` (the default FMUs, every parameter set
  by sblsim) step by step; the same host on the default FMUs runs another system (the check can fail);
* the outputs' declared ranges (min/max in ``modelDescription.xml``, from the declarations) hold at every step
  of both runs, and fmpy's validation of every scenario FMU finds nothing.

The fast tier builds ``lbl-field``'s scenario FMUs; ``usbl-deep``'s build (about 20 s) is in the slow tier.
"""

from __future__ import annotations

import subprocess
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave

from sblsim.fmus.build import beacons_dir, fmu_path, validate
from sblsim.models import MODELS
from sblsim.models.columns import TIMESERIES_COLUMNS
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.connections import default_connections
from sblsim.orchestrator.cosim.fmu_files import fmu_paths
from sblsim.orchestrator.cosim.plan import load_plan
from sblsim.orchestrator.cosim.run import run
from sblsim.orchestrator.cosim.ssp import export_ssp

SITES = ("lbl-field", "usbl-deep")
SEED = 3
TOL = 1e-9
SSV = "{http://ssp-standard.org/SSP1/SystemStructureParameterValues}"
HOST_TYPES = {"Real": "r", "Integer": "i", "Boolean": "b"}


@pytest.fixture(scope="module", params=[SITES[0], *(pytest.param(s, marks=pytest.mark.slow) for s in SITES[1:])])
def site(request, tmp_path_factory):
    """The scenario's plan (seed 3, Jacobi), its scenario FMUs (``sblsim fmus build --scenario``) and the SSP
    package ``sblsim ssp export`` makes of them (the FMUs in the folder the export reads for the scenario's
    interface)."""
    name = request.param
    plan = load_plan(name, ["simulation.master=jacobi"], SEED)
    root = tmp_path_factory.mktemp(name)
    folder = beacons_dir(root, plan.n_beacons)
    assert main(["fmus", "build", "--scenario", name, "--seed", str(SEED), "--out", str(folder)]) == 0
    ssp = export_ssp(plan, root / f"{name}.ssp", root)
    return name, plan, folder, ssp


def bound_values(ssp: Path) -> dict[str, dict[str, tuple[str, str]]]:
    """Component -> parameter -> (type, value text) of the package's ``.ssv`` files."""
    out = {}
    with zipfile.ZipFile(ssp) as archive:
        for member in archive.namelist():
            if member.startswith("resources/") and member.endswith(".ssv"):
                root = ET.fromstring(archive.read(member))
                out[Path(member).stem] = {p.get("name"): (p[0].tag.removeprefix(SSV), p[0].get("value"))
                                          for p in root.iter(f"{SSV}Parameter")}
    return out


def _number(text: str, kind: str):
    return {"Real": float, "Integer": int, "Boolean": lambda t: t == "true"}[kind](text)


def component_fmus(plan, folder: Path) -> dict[str, Path]:
    """Component -> its scenario FMU (the file name ``ssp export`` packs)."""
    return {component: fmu_path(folder, plan.model(component).name) for component in plan.sources}


@pytest.mark.slow
def test_every_bound_parameter_is_the_start_value_and_the_value_after_an_initialization_that_set_nothing(
        site, tmp_path):
    name, plan, folder, ssp = site
    bound = bound_values(ssp)
    fmus = component_fmus(plan, folder)
    assert sorted(bound) == sorted(fmus)
    differ = 0
    for component, fmu in fmus.items():
        md = read_model_description(str(fmu))
        variables = {v.name: v for v in md.modelVariables}
        model = plan.model(component)
        declared = {v.name: v.fmi_start for v in model.fmu_parameters_declared(plan.n_beacons)}
        slave = FMU2Slave(guid=md.guid, unzipDirectory=str(_unzip(fmu, tmp_path / component)),
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName=component)
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        try:
            for parameter, (kind, text) in bound[component].items():
                v = variables[parameter]
                assert v.causality == "parameter" and v.type == kind, (component, parameter)
                want = _number(text, kind)
                assert _number(v.start, kind) == want, (component, parameter, v.start, text)
                get = {"Real": slave.getReal, "Integer": slave.getInteger, "Boolean": slave.getBoolean}[kind]
                assert get([v.valueReference])[0] == want, (component, parameter)
                differ += want != declared[parameter]
        finally:
            slave.terminate()
            slave.freeInstance()
        assert md.defaultExperiment.stepSize == repr(plan.sampling_time / plan.ekf_rate_ratio)
        assert md.defaultExperiment.stopTime == repr(plan.n_steps * plan.sampling_time)
        assert f"scenario {name}, seed {SEED}" in md.description
    # the site is not the FMUs' ordinary defaults: many bound values differ from the declared starts
    assert differ >= 20, differ


def _unzip(fmu: Path, into: Path) -> Path:
    with zipfile.ZipFile(fmu) as archive:
        archive.extractall(into)
    return into


def host_run(c_host: Path, fmus: dict[str, Path], n_beacons: int, steps: int, h: float,
             into: Path) -> dict[str, np.ndarray]:
    """The C host's Jacobi run of the system (no parameter set): ``"component.output"`` -> values (steps,)."""
    order = list(fmus)
    lines, described, outputs = [], {}, []
    for component, fmu in fmus.items():
        folder = _unzip(fmu, into / component)
        md = read_model_description(str(fmu))
        described[component] = {v.name: v for v in md.modelVariables}
        binary = folder / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
        lines.append(f"fmu {binary} {md.guid} file://{folder}/resources")
    for c in default_connections(n_beacons):
        source, destination = described[c.source][c.output], described[c.destination][c.input]
        assert source.type == destination.type, c
        lines.append(f"link {order.index(c.source)} {source.valueReference} {order.index(c.destination)} "
                     f"{destination.valueReference} {HOST_TYPES[source.type]}")
    for component in order:
        for v in described[component].values():
            if v.causality == "output":
                outputs.append(f"{component}.{v.name}")
                lines.append(f"out {order.index(component)} {v.valueReference} {HOST_TYPES[v.type]}")
    done = subprocess.run([str(c_host), "--system", str(steps), repr(h)], input="\n".join(lines),
                          capture_output=True, text=True, env={}, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    rows = np.array([[float(x) for x in line.split()[2:]] for line in done.stdout.splitlines()])
    assert rows.shape == (steps, len(outputs))
    return {name: rows[:, k] for k, name in enumerate(outputs)}


@pytest.fixture(scope="module")
def host_and_sblsim(site, c_host, fmu_dir, tmp_path_factory):
    """The C host's run of the scenario FMUs, and ``sblsim run SCENARIO --engine fmu --master jacobi --seed 3``
    on the default FMUs."""
    name, plan, folder, _ = site
    assert plan.ekf_rate_ratio == 1  # the host steps every FMU at the base step, which is then T
    ours = run(plan, "fmu", fmu_dir=fmu_dir).timeseries
    host = host_run(c_host, component_fmus(plan, folder), plan.n_beacons, plan.n_steps, plan.sampling_time,
                    tmp_path_factory.mktemp(f"{name}-host"))
    return plan, host, ours


@pytest.mark.slow
def test_the_c_host_setting_nothing_gives_the_sblsim_run_step_by_step(host_and_sblsim, c_host, fmu_dir, tmp_path):
    plan, host, ours = host_and_sblsim
    assert len(ours) == plan.n_steps
    # every recorded column (truth, packet, channel, estimate, covariance, attitude), each the output it records
    for column, output in TIMESERIES_COLUMNS.items():
        np.testing.assert_allclose(host[output], ours[column].to_numpy(dtype=float), rtol=0, atol=TOL,
                                   err_msg=f"{column} ({output})")
    # the default FMUs (those sblsim ran) in the same host, setting nothing, run the straight fixed-loss channel
    defaults = fmu_paths(fmu_dir, dict(plan.sources), plan.n_beacons)
    other = host_run(c_host, defaults, plan.n_beacons, plan.n_steps, plan.sampling_time, tmp_path)
    # (over the steps where both have an estimate: neither has one before its first fix)
    assert np.nanmax(np.abs(other["receiver.est_x"] - ours["est_x"].to_numpy())) > 10.0


def test_outputs_stay_in_their_declared_ranges_and_fmpy_validates_the_scenario_fmus(site, host_and_sblsim):
    name, plan, folder, _ = site
    _, host, _ = host_and_sblsim
    ranged = 0
    for component, fmu in component_fmus(plan, folder).items():
        assert validate(fmu) == [], fmu.name
        md = read_model_description(str(fmu))
        declared = {v.name: v for v in MODELS[plan.model(component).name].outputs(plan.n_beacons)}
        for v in md.modelVariables:
            if v.causality != "output":
                continue
            want = declared[v.name]
            expected = tuple(None if x is None else float(x) for x in (want.min, want.max))
            got = tuple(None if x is None else float(x) for x in (v.min, v.max))
            assert got == expected, (v.name, got, expected)
            values = host[f"{component}.{v.name}"]
            if got[0] is not None:
                assert values.min() >= got[0], (name, v.name, values.min())
            if got[1] is not None:
                assert values.max() <= got[1], (name, v.name, values.max())
            ranged += got != (None, None)
    assert ranged >= 10, ranged
