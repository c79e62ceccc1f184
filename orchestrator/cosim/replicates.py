"""A plan's replicates simulated, the work of ``sblsim run`` and :func:`sblsim.run`: the kernel's run
(:func:`sblsim.orchestrator.cosim.run.run`) of ``run.replicate`` …, with an SSP package's connections and, on the
fmu engine, its FMUs when the run is of a package.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sblsim.orchestrator.cosim.engines import close_handles, make_handles
from sblsim.orchestrator.cosim.plan import RunPlan


def _simulate(plan: RunPlan, engine: str, replicates: int = 1, fmu_dir: str | Path | None = None,
              progress: Any = False, ssp: Any = None) -> Any:
    """Simulate a plan's replicates ``run.replicate`` … (``sblsim run`` and :func:`sblsim.run`); ``ssp``, an SSP
    package read back (:func:`sblsim.orchestrator.cosim.ssp_read.read_ssp`: its plan is ``plan``), brings its
    connections and, on the fmu engine, its FMUs."""
    from sblsim.orchestrator.cosim.run import run as _run

    handles, connections = None, None
    if ssp is not None:
        connections = ssp.connections
        handles = make_handles(engine, None, plan.n_beacons, dict(plan.sources),
                               fmu_files=ssp.fmu_files if engine == "fmu" else None)
    try:
        return _run(plan, engine, range(plan.replicate, plan.replicate + replicates), fmu_dir=fmu_dir,
                    handles=handles, progress=progress, connections=connections)
    finally:
        if handles is not None:
            close_handles(handles)
