"""Planning a campaign: the study's design cells split into chunks, each stepped as one batch."""

from __future__ import annotations

from dataclasses import dataclass, field

from sblsim.models import COMPONENTS
from sblsim.orchestrator.campaign.study import Study
from sblsim.orchestrator.cosim.plan import RunPlan

#: Default runs per chunk on each engine.
DEFAULT_BATCH = {"local": 800, "fmu": 50}


@dataclass
class Chunk:
    """Consecutive design cells of one scenario, stepped as one batch.

    Attributes
    ----------
    id : str
        File stem, ``SCENARIOKEY-FIRSTCELL-LASTCELL``.
    scenario : str
    cells : list of int
    plans : list of RunPlan
        The plan of each cell (replicate 0), resolved once; the cell's replicates share it.
    replicates : int
    steps : int
        Macro steps per run (cost estimate).
    """

    id: str
    scenario: str
    cells: list[int]
    plans: list[RunPlan] = field(repr=False)
    replicates: int = 1
    steps: int = 0

    @property
    def runs(self) -> int:
        return len(self.cells) * self.replicates


def batch_key(cfg: RunPlan | dict) -> tuple:
    """What the runs of one batch must share: the simulation settings, every text value and every
    configuration-only key (they make tables or files); numeric FMU parameters may differ per run."""
    key = [("simulation", name, value) for name, value in sorted(cfg["simulation"].items())]
    for section, model in COMPONENTS.items():
        fmu = model.fmu_parameter_names()
        key.extend((section, name, value) for name, value in sorted(cfg[section].items())
                   if isinstance(value, str) or name not in fmu)
    return tuple(key)


def cell_configs(study: Study) -> dict[str, list[RunPlan]]:
    """The plan of every design cell of every scenario (replicate 0), each cell resolved once.

    Raises
    ------
    ConfigError, ModelError
        If a design cell does not make a valid configuration.
    """
    return {scenario: [study.cell_plan(scenario, c) for c in range(study.cells)] for scenario in study.scenarios}


def plan(study: Study, batch: int, configs: dict[str, list[RunPlan]] | None = None) -> list[Chunk]:
    """Split a study into chunks of at most ``batch`` runs (at least one cell each).

    Cells are grouped by :func:`batch_key` in design order; the plan depends
    only on the study and ``batch``.
    """
    configs = configs if configs is not None else cell_configs(study)
    chunks = []
    per_chunk = max(1, batch // study.replicates)
    for scenario in study.scenarios:
        groups: dict[tuple, list[int]] = {}
        for c, cfg in enumerate(configs[scenario]):
            groups.setdefault(batch_key(cfg), []).append(c)
        for cells in groups.values():
            for start in range(0, len(cells), per_chunk):
                part = cells[start:start + per_chunk]
                cfg = configs[scenario][part[0]]
                steps = cfg.n_steps * cfg.ekf_rate_ratio
                chunks.append(Chunk(f"{cfg['run']['scenario_key']:03d}-{part[0]:05d}-{part[-1]:05d}", scenario,
                                    part, [configs[scenario][c] for c in part], study.replicates, steps))
    return chunks
