"""The check of the figures a page quotes (tests/page_figures.py): it reads the markers, finds a wrong figure in a
small page made here, and the pages' prose agrees with their own printed blocks (the run itself is checked by
tests/test_readme.py, in the slow tier)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.page_figures import check_page, check_prose, figures, prose_figures, regions, skeleton

ROOT = Path(__file__).resolve().parents[1]
#: The pages whose figures are marked, and the least each marks (printed blocks, prose figures).
MARKED = {"docs/tracking.md": (3, 20), "docs/sync.md": (8, 15)}

PAGE = """# A page

```bash
sblsim sync detections.csv --out results/s
```

It prints (in 7 s):

<!-- printed -->
```text
sync of detections.csv: 22807 arrivals of 45202 detections in 4.9 s
  median |residual| 1.79 m, NEES 24.4
```

```python
print("| tag | pings | flagged | median σ [m] |")
print("|---:|---:|---:|---:|")
print("| cod | 1,786 | 66 | 2.10 |")
print("| lobster | 1,233 | 505 | 5.76 |")
```

<!-- printed -->
| tag | pings | flagged | median σ [m] |
|---|---|---|---|
| cod | 1,786 | 66 | 2.10 |
| lobster | 1,233 | 505 | 5.76 |

The cod has **66** <!-- figure: cod · flagged --> rows flagged, a median σ of 2.1 m <!-- figure: cod · median σ [m] -->,
the residuals 1.8 m <!-- figure: "median |residual|" --> and the lobster 1,233 <!-- figure: lobster · pings -->
pings; its speed 1,458.5 m/s <!-- figure: results/s/summary.json sound_speed.value --> and
12 <!-- figure: results/s/summary.json counts[1] --> rows.
"""

OUTPUT = {
    3: "sync of detections.csv: 22807 arrivals of 45202 detections in 6.3 s\n  median |residual| 1.80 m, NEES 24.1\n"
       "note: something else\n",
    15: "| tag | pings | flagged | median σ [m] |\n|---:|---:|---:|---:|\n| cod | 1,786 | 66 | 2.10 |\n"
        "| lobster | 1,233 | 505 | 5.76 |\n",
}


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "results" / "s").mkdir(parents=True)
    (tmp_path / "results" / "s" / "summary.json").write_text(
        json.dumps({"sound_speed": {"value": 1458.47}, "counts": [3, 12]}))
    return tmp_path


def test_figures_are_read_as_written():
    read = figures("| full array | 3,022 | 0.243 | 1.1e+03 | +1.45 | −0.5 | H4 | 2-D | 2023-09-01")
    assert [f.value for f in read] == [3022, 0.243, 1100, 1.45, -0.5, 2, 2023, 9, 1]
    assert [f.count for f in read[:4]] == [True, False, False, False]
    assert read[1].unit == pytest.approx(0.001) and read[3].unit == pytest.approx(0.01)
    assert read[2].unit == pytest.approx(100)  # 1.1e+03: its last digit is the hundreds
    # a timing is no figure of the line's shape; a separator row is one whatever its alignment marks
    assert skeleton("a 12 in 4.9 s") == skeleton("a   13 in 0.2 s") == "a # in <time> s"
    assert skeleton("|---:|:--|") == skeleton("|---|---|")


def test_the_markers_are_read():
    found = regions(PAGE)
    assert [(r.line, r.table, r.blocks) for r in found] == [(11, False, [3]), (23, True, [15])]
    assert found[0].lines[1] == "  median |residual| 1.79 m, NEES 24.4"
    keys = [(line, f.text if f else None, key) for line, f, key in prose_figures(PAGE)]
    assert keys == [(28, "66", "cod · flagged"), (28, "2.1", "cod · median σ [m]"),
                    (29, "1.8", '"median |residual|"'), (29, "1,233", "lobster · pings"),
                    (30, "1,458.5", "results/s/summary.json sound_speed.value"),
                    (31, "12", "results/s/summary.json counts[1]")]


def test_a_page_that_agrees_with_its_run_passes(folder):
    assert check_page(PAGE, OUTPUT, folder) == []
    assert check_prose(PAGE) == []  # without a run: the prose against the page's printed blocks


@pytest.mark.parametrize("wrong, right, says", [
    ("| 1,233 | 505 | 5.76 |\n\nThe", "| 1,233 | 507 | 5.76 |\n\nThe", "507 where the run printed 505"),
    ("| 505 | 5.76 |\n\nThe", "| 505 | 5.96 |\n\nThe", "5.96 where the run printed 5.76"),
    ("NEES 24.4", "NEES 26.4", "26.4 where the run printed 24.1"),
    ("22807 arrivals", "22870 arrivals", "22870 where the run printed 22807"),
    ("NEES 24.4", "NEES: 24.4", "not printed by the run"),
    ("**66** <!--", "**65** <!--", "65 where the page's printed block has 66"),
    ("2.1 m <!--", "2.2 m <!--", "2.2 where the page's printed block has 2.10"),
    ("1.8 m <!--", "1.7 m <!--", "1.7 where the page's printed block has 1.79"),
    ("1.8 m <!--", "1.78 m <!--", "1.78 where the page's printed block has 1.79"),  # as many digits: the same
    ("1,458.5 m/s", "1,412.5 m/s", "1,412.5 where the run wrote 1458.47"),
    ("12 <!--", "13 <!--", "13 where the run wrote 12"),
    ("counts[1]", "counts[7]", "has no 'counts[7]'"),
    ("cod · flagged", "cod · caught", "0 printed tables of the page have one row 'cod' and a column 'caught'"),
])
def test_a_wrong_figure_is_found_and_named(folder, wrong, right, says):
    assert PAGE.count(wrong) == 1
    problems = check_page(PAGE.replace(wrong, right), OUTPUT, folder)
    assert len(problems) == 1 and says in problems[0], problems


def test_tolerances_figures_within_3_percent_counts_exact_timings_free(folder):
    moved = dict(OUTPUT)
    moved[3] = OUTPUT[3].replace("24.1", "25.1").replace("6.3 s", "60.3 s")  # 24.4 against 25.1: 2.8 % off
    assert check_page(PAGE, moved, folder) == []
    moved[3] = OUTPUT[3].replace("24.1", "25.3")  # 3.6 % off
    assert "24.4 where the run printed 25.3" in check_page(PAGE, moved, folder)[0]
    assert check_page(PAGE.replace("<!-- printed -->\n```text", "<!-- printed ±5 % -->\n```text"), moved,
                      folder) == []
    (folder / "results" / "s" / "summary.json").write_text(
        json.dumps({"sound_speed": {"value": 1458.47 * 1.029}, "counts": [3, 12]}))
    assert check_page(PAGE, OUTPUT, folder) == []
    tight = PAGE.replace("sound_speed.value -->", "sound_speed.value ±1 % -->")
    assert "1,458.5 where the run wrote 1500.77" in check_page(tight, OUTPUT, folder)[0]
    assert check_page(PAGE, {3: OUTPUT[3]}, folder) == ["line 23: the blocks at lines [15] did not run"]


def test_a_marker_without_its_figure_or_block_is_refused():
    assert check_prose("Some words <!-- figure: cod · flagged -->\n")[0].startswith("line 1: no figure just before")
    assert check_prose("<!-- printed -->\n| a |\n|---|\n| 1 |\n") == [
        "line 1: '<!-- printed -->' follows no block that runs"]
    assert check_prose("x 12 <!-- figure: cod -->\n")[0].startswith("line 1: the key 'cod' is neither")


@pytest.mark.parametrize("page", sorted(MARKED))
def test_the_pages_prose_agrees_with_their_printed_blocks(page):
    """Each figure of the prose marked with a printed block's cell or line is that figure, rounded; the printed
    blocks themselves and the figures of the files are checked against the run (tests/test_readme.py)."""
    text = (ROOT / page).read_text()
    assert check_prose(text) == []
    least_printed, least_prose = MARKED[page]
    assert len(regions(text)) >= least_printed
    assert len(prose_figures(text)) >= least_prose


def test_counts_named_for_a_table_and_markers_quoted_in_code():
    page = PAGE.replace("<!-- printed -->\n| tag |", "<!-- printed; counts: pings -->\n| tag |")
    assert regions(page)[1].counts == ("pings",)
    moved = dict(OUTPUT)
    moved[15] = OUTPUT[15].replace("| 505 |", "| 510 |")  # 1 % off: a figure, not a count, in that table
    assert check_page(page, moved, None) == []  # (None: the files are not checked)
    assert check_page(PAGE, moved, None)[0].startswith("line 26: 505 where the run printed 510")
    moved[15] = OUTPUT[15].replace("| 1,233 |", "| 1,234 |")  # a count of the column named
    assert "1,233 where the run printed 1,234" in check_page(page, moved, None)[0]
    with pytest.raises(ValueError, match="names no column"):
        regions(PAGE.replace("<!-- printed -->\n| tag |", "<!-- printed; counts: rows -->\n| tag |"))
    # a marker quoted in inline code (a page describing them) is none
    assert prose_figures("Mark it `12 <!-- figure: cod · flagged -->` so.\n") == []
