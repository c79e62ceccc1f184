"""A design problem's candidates (:mod:`~sblsim.orchestrator.design.run`'s step 2): per system, every count (LBL
transponders) and combination of the grades that change that system's accuracy
(:data:`~sblsim.orchestrator.design.keys.GRADES`), with its cost, in the order of their cost; and the overrides of
the base scenario that make a candidate's grades and layout.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.design.keys import GRADES, SYSTEM_NAMES
from sblsim.orchestrator.design.resolution import Resolved


@dataclass
class Candidate:
    """A system with a count and grades, and its cost (the layout is searched)."""

    system: str
    count: int
    grades: dict[str, str]
    cost: float
    order: int = 0
    kept: int = 0

    @property
    def label(self) -> str:
        grades = ", ".join(f"{k} {v}" for k, v in self.grades.items())
        what = f"{self.system.upper()}, {self.count} {SYSTEMS[self.system].marker}"
        what += f" ({self.kept} in place)" if self.kept else ""
        return what + (f", {grades}" if grades else "")

    @property
    def layout(self) -> str:
        """How the system's transducers are placed (:attr:`~sblsim.models.systems.System.design_layout`)."""
        return SYSTEMS[self.system].design_layout


def candidates(resolved: Resolved) -> list[Candidate]:
    """Every candidate of the problem, in the order of cost (then of the systems, counts and grades as listed).

    With transponders in place (:attr:`~sblsim.orchestrator.design.resolution.Resolved.kept`, k of them), an LBL's
    counts start at k and only the transponders added are paid for."""
    c = resolved.sections["candidates"]
    kept = len(resolved.kept)
    out = []
    for name in [s for s in SYSTEM_NAMES if s in c["systems"]]:
        system = SYSTEMS[name]
        categories = [k for k in system.design_grades if c[k]]
        choices = [[(k, grade, (c[f"{k}_cost"] or [0.0] * len(c[k]))[i]) for i, grade in enumerate(c[k])]
                   for k in categories]
        paid = 0
        if system.design_layout == "seafloor":  # each transponder added paid
            counts = range(max(c["transponders"][0], kept), c["transponders"][1] + 1)
            base, each, paid = 0.0, c["transponder_cost"], kept
        else:  # the system paid: an SBL's beacons on their circle, or one transceiver
            counts = [c["sbl_beacons"] if system.design_layout == "platform" else 1]
            base, each = c.get(f"{name}_cost", 0.0), 0.0
        for count in counts:
            for combo in itertools.product(*choices):
                cost = base + (count - paid) * each + sum(x[2] for x in combo)
                out.append(Candidate(name, count, {k: g for k, g, _ in combo}, float(cost), len(out), paid))
    return sorted(out, key=lambda x: (x.cost, x.order))


def grade_items(candidate: Candidate) -> list[str]:
    """The overrides of a candidate's grades (:data:`~sblsim.orchestrator.design.keys.GRADES`)."""
    return [f"{GRADES[k][g][0]}={GRADES[k][g][1]!r}" for k, g in candidate.grades.items()]


def layout_items(system: str, count: int, transponders: np.ndarray | None = None,
                 baseline: float | None = None) -> list[str]:
    """The overrides of a system's layout (:meth:`~sblsim.models.systems.System.design_items`)."""
    return SYSTEMS[system].design_items(count, transponders, baseline)


__all__ = ["Candidate", "candidates", "grade_items", "layout_items"]
