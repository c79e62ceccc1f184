"""A run is resolved once: the plan (``sblsim.orchestrator.cosim.plan``) is typed and frozen, an invalid configuration
fails when its plan is made, and every entry point resolves each configuration exactly once."""

from __future__ import annotations

import dataclasses
import importlib
import pickle
import pkgutil
import sys

import numpy as np
import pytest

import sblsim
import sblsim.orchestrator
import sblsim.orchestrator.cosim.config as config_module
import sblsim.orchestrator.cosim.plan as plan_module
from sblsim.models.errors import ConfigError
from sblsim.models.systems import SYSTEMS, System
from sblsim.orchestrator.campaign.study import load_study
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.plan import RunPlan, load_plan, make_plan, thaw
from sblsim.orchestrator.montecarlo.error_sources import SOURCES

SHORT = ["simulation.duration=2"]


# --------------------------------------------------------------------------- typed and frozen

def test_the_plan_is_typed_and_its_fields_are_the_configurations():
    plan = load_plan("semicircle", ["receiver=lsq", "receiver.latency=0.3", "simulation.duration=5",
                                    "simulation.ekf_rate_ratio=2"], seed=7)
    assert isinstance(plan, RunPlan) and isinstance(plan.system, System)
    assert plan.system is SYSTEMS[plan["platform"]["system"]] is SYSTEMS["sbl"]
    assert (plan.n_beacons, plan.receiver, plan.receiver_label) == (4, "lsq", "lsq")
    assert plan.sources["receiver"] == "receiver_lsq" and plan.sources["platform"] == "platform"
    assert plan.latency_steps == 3 and plan.n_steps == 50 and plan.ekf_rate_ratio == 2
    assert (plan.seed, plan.replicate, plan.scenario) == (7, 0, "semicircle")
    assert plan.sampling_time == 0.1 and plan.rates == {"receiver": 2}
    # the receiver's clock and the slot period are the orchestrator's ties of T, the latency never a parameter
    receiver = plan.component_parameters("receiver")
    assert receiver["communication_step"] == pytest.approx(0.05) and "latency" not in receiver
    assert plan.component_parameters("acoustics")["slot_period"] == 0.1
    # the lever arms are the cross of the configured baseline at the transducer depth
    p = plan["platform"]
    b, d = p["baseline"], p["transducer_depth"]
    assert sorted(map(tuple, plan.lever_arms.round(12))) == sorted([(b, 0, d), (0, b, d), (-b, 0, d), (0, -b, d)])
    assert plan.horizontal_spread == pytest.approx(2 * b)


def test_the_plan_refuses_every_change():
    plan = load_plan("semicircle")
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.n_beacons = 6
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.system = SYSTEMS["usbl"]
    with pytest.raises(TypeError):
        plan["platform"]["baseline"] = 30.0
    with pytest.raises(TypeError):
        plan.config["platform"] = {}
    with pytest.raises(TypeError):
        plan.config["run"].update(seed=3)
    with pytest.raises(TypeError):
        plan.parameters["platform"]["baseline"] = 30.0
    with pytest.raises(ValueError):
        plan.lever_arms[0, 0] = 1.0
    assert plan["platform"]["baseline"] == load_config("semicircle")["platform"]["baseline"]


def test_the_plan_owns_its_configuration():
    cfg = load_config("semicircle")
    plan = make_plan(cfg)
    cfg["platform"]["baseline"] = 50.0  # the caller's dict is not the plan's
    assert plan["platform"]["baseline"] != 50.0
    changed = thaw(plan)  # a changeable copy, whose plan is a new one
    changed["platform"]["baseline"] = 50.0
    assert make_plan(changed).lever_arms.max() == pytest.approx(50.0) and plan.lever_arms.max() < 50.0


def test_a_replicate_shares_the_plan_and_a_pickled_plan_is_the_same(monkeypatch):
    plan = load_plan("semicircle", ["platform.system=usbl"])
    monkeypatch.setattr(plan_module, "resolve", lambda raw: pytest.fail("resolved again"))
    other = plan.with_replicate(5)
    assert other.replicate == 5 and other["run"]["replicate"] == 5 and plan["run"]["replicate"] == 0
    assert other.bound is plan.bound and other.system is plan.system
    back = pickle.loads(pickle.dumps(other))  # what a campaign's worker receives
    assert back == other and back.system is SYSTEMS["usbl"] and back.sources == other.sources
    np.testing.assert_array_equal(back.lever_arms, other.lever_arms)
    assert not back.lever_arms.flags.writeable


# --------------------------------------------------------------------------- an invalid configuration fails once

def test_an_invalid_configuration_fails_when_the_plan_is_made():
    with pytest.raises(ConfigError, match=r"^platform\.baseline: "):
        load_plan("semicircle", ["platform.baseline=-1"])
    raw = thaw(load_config("semicircle"))
    raw["receiver"]["latency"] = 0.05  # half a sampling time
    with pytest.raises(ConfigError, match=r"^receiver\.latency: 0\.05 s is not a whole number"):
        make_plan(raw)


def test_the_api_fails_before_any_simulation(monkeypatch):
    import sblsim.orchestrator.cosim.run as run_module

    _every_module()
    for name, module in list(sys.modules.items()):
        if name.startswith("sblsim") and getattr(module, "run_batch", None) is run_module.run_batch:
            monkeypatch.setattr(module, "run_batch", lambda *a, **k: pytest.fail("simulated an invalid configuration"))
    with pytest.raises(ConfigError, match=r"^platform\.baseline: "):
        sblsim.run("semicircle", set={"platform.baseline": -1})
    with pytest.raises(ConfigError, match=r"^platform\.baseline: "):
        sblsim.compare("semicircle", receivers="ekf,lsq", set={"platform.baseline": -1})


# --------------------------------------------------------------------------- one resolution per configuration

def _every_module() -> None:
    for info in pkgutil.walk_packages(sblsim.orchestrator.__path__, "sblsim.orchestrator."):
        if not info.name.endswith("__main__"):
            importlib.import_module(info.name)


@pytest.fixture
def counted(monkeypatch):
    """Count every validation of a configuration (:func:`config.resolve`, wherever it is called from) and every
    plan made (:func:`plan.make_plan`)."""
    _every_module()
    counts = {"resolve": 0, "plan": 0}
    original = {"resolve": config_module.resolve, "plan": plan_module.make_plan}

    def counter(kind):
        def wrapped(*args, **kwargs):
            counts[kind] += 1
            return original[kind](*args, **kwargs)
        return wrapped

    wrapped = {kind: counter(kind) for kind in original}
    for name, module in list(sys.modules.items()):
        if name.startswith("sblsim") and module is not None:
            for attr, kind in (("resolve", "resolve"), ("make_plan", "plan")):
                if getattr(module, attr, None) is original[kind]:
                    monkeypatch.setattr(module, attr, wrapped[kind])
    return counts


def _once(counts, n, plans=None):
    assert counts == {"resolve": n, "plan": n if plans is None else plans}
    counts.update(resolve=0, plan=0)


def test_a_run_is_resolved_once(counted):
    sblsim.run("semicircle", set=SHORT, replicates=3)
    _once(counted, 1)
    cfg = sblsim.load("semicircle", set=SHORT)
    _once(counted, 1, plans=0)  # a Config: validated, no plan (each function makes its own, once)
    result = sblsim.run(cfg, seed=2)
    assert len(result.summaries) == 1
    _once(counted, 1)
    plan = plan_module.make_plan(cfg)
    _once(counted, 1)
    sblsim.run(plan)  # a plan is taken as it is
    _once(counted, 0)


def test_a_comparison_resolves_each_system_and_receiver_once(counted):
    result = sblsim.compare("semicircle", receivers="ekf,lsq", systems="sbl,usbl", replicates=2, set=SHORT)
    assert len(result.table) == 4
    _once(counted, 4)


def test_a_budget_resolves_each_of_its_configurations_once(counted):
    b = sblsim.budget("semicircle", replicates=2, set=SHORT)
    each = 1 + len(SOURCES) + 1  # all on, each source off, every source off (the floor)
    _once(counted, each)
    assert len(b.budgets) == 1
    sblsim.budget("semicircle", replicates=2, set=SHORT, compare="platform.system=sbl,usbl")
    _once(counted, 2 * each)


def test_a_map_resolves_each_configuration_once(counted):
    m = sblsim.accuracy_map("semicircle", extent=4.0, step=1.0)
    _once(counted, 1)
    m.plot()
    _once(counted, 0)
    sblsim.accuracy_map("semicircle", extent=4.0, step=1.0, compare="platform.baseline=1,2,3")
    _once(counted, 3)


def test_a_replay_is_resolved_once(counted, tmp_path):
    from sblsim.orchestrator.logs.log_export import export_log

    result = sblsim.run("semicircle", seed=1, set=SHORT)
    log, truth = export_log(result._result, tmp_path / "log.csv")
    counted.update(resolve=0, plan=0)
    r = sblsim.replay(log, truth=truth)
    assert r.summary["steps"] == 20
    _once(counted, 1)


def test_a_campaign_resolves_each_cell_once(counted, tmp_path):
    study = load_study({"study": {"name": "small", "scenarios": ["semicircle"], "replicates": 3,
                                  "set": ["simulation.duration=1"]},
                        "factors": [{"name": "B", "key": "platform.baseline", "low": 1.0, "high": 3.0},
                                    {"name": "S", "key": "acoustics.sigma_range", "low": 0.01, "high": 0.1}]})
    counted.update(resolve=0, plan=0)
    result = sblsim.campaign(study, tmp_path / "c", workers=1, batch=3)  # a chunk per cell, three replicates each
    assert result.total == 4 * 3 and result.computed == 12
    _once(counted, 4)


@pytest.mark.slow
def test_an_ssp_export_and_its_run_are_resolved_once(counted, fmu_dir, tmp_path):
    from sblsim.orchestrator.cli import main

    out = tmp_path / "s.ssp"
    assert main(["ssp", "export", "semicircle", "--out", str(out), "--fmu-dir", str(fmu_dir), "--set", SHORT[0]]) == 0
    _once(counted, 1)
    assert main(["run", "--ssp", str(out), "--engine", "local", "--out", str(tmp_path / "r")]) == 0
    _once(counted, 1)  # the package read back into one plan
