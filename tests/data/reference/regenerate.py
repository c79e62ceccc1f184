"""Write the reference results: ``summary.json`` of every built-in scenario at seed 1 (local engine).

Run ``python tests/data/reference/regenerate.py`` after a change that is meant to change the numbers, and say
why in the commit; it prints the rows of the Results table, to paste into the README's and docs/usage.md's
tables. ``tests/orchestrator/test_reference.py`` compares fresh runs and those tables with these files.
"""

from __future__ import annotations

import json
from pathlib import Path

from sblsim.orchestrator.cosim.config import BUILTIN_SCENARIOS, load_config
from sblsim.orchestrator.cosim.run import run
from sblsim.orchestrator.cosim.run_output import summary

HERE = Path(__file__).resolve().parent

#: What a reference keeps of summary.json (not the wall time, which is the machine's).
VOLATILE = ("wall_time",)
SEED = 1
#: The columns of the README's and docs/usage.md's Results table, after the scenario's name.
COLUMNS = ("steps", "e_x_mean", "e_y_mean", "e_z_mean", "e_tot_mean", "e_tot_rms", "instr_e_tot_mean",
           "instr_e_tot_rms")


def table_cells(ref: dict) -> list[str]:
    """A reference's cells of the Results table (after the name): the steps, then the errors to the millimetre."""
    return [str(ref["steps"])] + [f"{ref[c]:.3f}" for c in COLUMNS[1:]]


def reference(name: str) -> dict:
    """The reference summary of a built-in scenario at :data:`SEED`."""
    result = run(load_config(name, seed=SEED), "local")
    return {k: v for k, v in summary(result).items() if k not in VOLATILE}


if __name__ == "__main__":
    for name in BUILTIN_SCENARIOS:
        path = HERE / f"{name}.json"
        path.write_text(json.dumps(reference(name), indent=2, allow_nan=False) + "\n")
        print(f"wrote {path}")
    for name in BUILTIN_SCENARIOS:  # the Results table's rows
        print("| " + " | ".join([name, *table_cells(json.loads((HERE / f"{name}.json").read_text()))]) + " |")
