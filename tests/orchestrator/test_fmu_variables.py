"""docs/variables.md holds the variable tables generated from the declarations, and they cover every variable."""

from pathlib import Path

from sblsim.fmus.variables import BEGIN, END, markdown_tables
from sblsim.models import MODELS

PAGE = Path(__file__).parents[2] / "docs" / "variables.md"


def test_docs_tables_equal_the_generated_ones():
    text = PAGE.read_text()
    start, stop = text.index(BEGIN), text.index(END) + len(END)
    assert text[start:stop] == markdown_tables(), "regenerate with `sblsim fmus variables`"


def test_tables_list_every_variable_with_its_unit():
    tables = markdown_tables()
    for name, model in MODELS.items():
        block = tables.split(f"**`sblsim_{name}.fmu`**")[1].split("**`sblsim_")[0]
        rows = [line for line in block.splitlines() if line.startswith("| `")]
        expected = []
        for v in model.fmu_variables():
            if v.in_table:
                continue
            if v.name.startswith("lane"):  # a later lane of a delivery: one row for them all
                lane, field = v.name[4:].split("_", 1)
                if lane == "2":
                    expected.append((f"`lane<m>_{field}` (m = 2…8)", v.causality, v.variability, v.fmi_type, v.unit))
                continue
            expected.append((f"`{v.name}`", v.causality, v.variability, v.fmi_type, v.unit))
            if v.table is not None:
                expected += [(f"`{c.name}[1..{v.table.max_rows}]`", "parameter", "fixed", "Real", c.unit)
                             for c in v.table.columns]
        assert len(rows) == len(expected)
        for row, cells in zip(rows, expected):
            assert tuple(c.strip() for c in row.strip("|").split("|"))[:5] == cells
