"""FMUs that carry a scenario: ``sblsim fmus build --scenario NAME|CONFIG.toml [--seed N] [--receiver NAME]``.

The scenario's components (the set and file names ``sblsim ssp export`` packs: ``sblsim_platform.fmu``,
``sblsim_acoustics.fmu``, ``sblsim_target.fmu`` and the receiver's) are built with that scenario's parameter
values, the values of the package's ``.ssv`` files, as their start values in ``modelDescription.xml`` and
as the defaults compiled into their binaries; their default experiment is the scenario's (the base step
``T / ekf_rate_ratio``, the duration). A host that sets no parameter, such as the FMI Compliance Checker or
a tool into which the FMUs are dragged, therefore runs the scenario: connected as ``default_connections``
and stepped by a Jacobi master, it gives the numbers of ``sblsim run SCENARIO --engine fmu --master jacobi``
with the same seed. Every variable stays: a host may still set any parameter before initialization.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from sblsim.fmus.build import build_fmu, version_dir
from sblsim.models.errors import ModelError
from sblsim.orchestrator.cosim.plan import RunPlan


def check_no_latency(plan: RunPlan, what: str, error: type[Exception]) -> None:
    """Raise ``error`` if ``receiver.latency`` > 0: the orchestrator delays the receiver's recorded outputs after
    a run, and an FMI host stepping the exported system (SSP package or scenario FMUs) would show them undelayed
    (other numbers than ``sblsim run``)."""
    latency = plan["receiver"].get("latency", 0.0)
    if latency > 0.0:
        raise error(f"receiver.latency: {latency:g} s cannot be {what}: the orchestrator delays the receiver's "
                    f"outputs after a run, an FMI host would show them undelayed; use receiver.latency = 0")


def build_scenario_fmus(plan: RunPlan, out: Path | str, compiler: str = "auto", cross: bool | None = None,
                        report: Callable[[str], object] | None = None, fmi_version: int = 2) -> list[Path]:
    """Build a run plan's FMUs with its parameter values as their start values and compiled-in defaults.

    Parameters
    ----------
    plan : RunPlan
        The scenario's plan (:func:`sblsim.orchestrator.cosim.plan.load_plan`), seed and replicate included.
    out : path
        The folder to write ``sblsim_<model>.fmu`` into (created if missing; each file replaced atomically); the
        FMI 3.0 FMUs go to its folder ``fmi3`` (:func:`sblsim.fmus.build.version_dir`).
    compiler, cross, report, fmi_version
        As :func:`sblsim.fmus.build.build_fmu`.

    Returns
    -------
    list of Path
        The FMUs, in the order of the plan's components.

    Raises
    ------
    ModelError
        If the receiver is a user's FMU (``fmu:PATH``: its binary cannot be given other defaults), or
        ``receiver.latency`` is not 0 (the orchestrator delays the receiver's outputs after a run; a host
        would show them undelayed).
    CompileError
        If the compiler is missing or fails.
    """
    check_no_latency(plan, "built into FMUs", ModelError)
    n_beacons = plan.n_beacons
    models = {component: plan.model(component) for component in plan.sources}
    for component, model in models.items():
        if model is None:
            raise ModelError(f"{component}: {plan.sources[component]} is an FMU; a scenario is built into the "
                             "FMUs sblsim generates (a receiver named ekf, ekf-seq, ukf, lsq or model:PATH.py)")
    experiment = (plan.sampling_time / plan.ekf_rate_ratio, plan.n_steps * plan.sampling_time)
    built_for = f"scenario {plan.scenario}, seed {plan.seed}"
    paths = []
    for component, model in models.items():
        values = plan.component_parameters(component, model.fmu_parameter_names(n_beacons))
        paths.append(build_fmu(model, version_dir(out, fmi_version), n_beacons, compiler=compiler, cross=cross,
                               report=report, parameters=values, experiment=experiment, built_for=built_for,
                               fmi_version=fmi_version))
    return paths


__all__ = ["build_scenario_fmus", "check_no_latency"]
