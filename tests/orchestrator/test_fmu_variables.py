"""The README's variable tables are the ones generated from the declarations, and cover every variable."""

from pathlib import Path

from fmus.variables import BEGIN, END, markdown_tables
from models import CORES

README = Path(__file__).parents[2] / "README.md"


def test_readme_tables_equal_the_generated_ones():
    text = README.read_text()
    start, stop = text.index(BEGIN), text.index(END) + len(END)
    assert text[start:stop] == markdown_tables(), "regenerate with `sblsim fmus variables`"


def test_tables_list_every_variable_with_its_unit():
    tables = markdown_tables()
    for name, core in CORES.items():
        block = tables.split(f"**`sblsim_{name}.fmu`**")[1].split("**`sblsim_")[0]
        rows = [line for line in block.splitlines() if line.startswith("| `")]
        declared = core.variables()
        assert len(rows) == len(declared)
        for row, v in zip(rows, declared):
            cells = [c.strip() for c in row.strip("|").split("|")]
            assert cells[:4] == [f"`{v.name}`", v.causality, v.type, v.unit]
