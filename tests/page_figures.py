"""The figures a documentation page quotes, checked against what the page's own blocks print and write.

A page marks what comes from a run with HTML comments, which the rendered site does not show
(docs/extending.md, "Figures a page quotes", is the developers' description):

* ``<!-- printed -->`` on its own line just before a fenced ``text`` block, a Markdown table or a paragraph: that
  block is what the page's blocks run since the previous ``printed`` marker print (the same blocks again where none
  ran in between). Each of its lines must be a line those blocks printed (on stdout or stderr), with the same words;
  a paragraph is one printed line, wrapped. Its figures must agree: a count (an integer on both sides) exactly,
  another figure within :data:`TOLERANCE` of the printed one or one unit of the page's last digit; a timing
  (``in 4.9 s``) is not compared. ``<!-- printed ±10 % -->`` gives another tolerance; ``<!-- printed; counts: pings,
  gaps -->`` before a table makes only those columns' integers counts (a figure printed to 3 significant digits,
  ``798``, is an integer too).
* ``FIGURE <!-- figure: KEY -->`` after a figure in the prose (a unit may stand between them): the figure is
  taken from ``KEY``, one of

  - ``ROW · COLUMN`` (``ROW`` one label or several, `` · `` between): the cell, in the column of that header, of
    the one row those labels start of the one printed table of the page where they pick one row; the figure is
    that cell rounded (within half a unit of the last digit of each; the same figure where the prose gives as
    many digits, and a count);
  - ``"PHRASE"``: the first figure after ``PHRASE`` in the one line of the page's printed blocks holding it, rounded;
  - ``FILE KEY`` (``FILE`` ending in ``.json``, from the folder the page's blocks run in; ``KEY`` a dotted path,
    ``[i]`` for an item of a list): the value the run wrote, a count exactly, another figure within
    :data:`TOLERANCE` (or the tolerance the key ends with, ``… ±0.1 %``) or half a unit of the page's last digit.

The first two need no run (the fast tier checks them: the prose against the page's own printed blocks); the printed
blocks and the files are checked after the page's blocks have run (tests/test_readme.py, the slow tier), so a
figure of the prose follows the run through the printed block it names.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

#: The relative tolerance of a figure against the run [-] (a count is exact).
TOLERANCE = 0.03
#: A figure: a sign where it is not a hyphen, digits (thousands by commas), a fraction, an exponent.
NUMBER = re.compile(r"(?<![\w.,])([-+−]?)(\d{1,3}(?:,\d{3})+|\d+)(\.\d+)?(?:[eE]([-+]?\d+))?(?![\w])")
#: A timing in a printed line (``in 4.9 s``): not compared.
TIMING = re.compile(r"\bin \d+(?:\.\d+)? s\b")
PRINTED = re.compile(r"^<!--\s*printed(?:\s+±\s*(\d+(?:\.\d+)?)\s*%)?(?:\s*;\s*counts:\s*(.*?))?\s*-->\s*$")
FIGURE = re.compile(r"<!--\s*figure:\s*(.*?)\s*-->")
FENCE = re.compile(r"^```(\S*)\n(.*?)^```$", flags=re.S | re.M)
#: What may stand between a prose figure and its marker: emphasis, code marks, a unit.
BETWEEN = re.compile(r"[\s*_`]*(?:[^\W\d_][\w/²³°%]*|%|°|µ\w*)?[\s*_`]*")
SEPARATOR = re.compile(r"^\|?(\s*:?-+:?\s*\|)+\s*:?-*:?\s*$")


@dataclass(frozen=True)
class Figure:
    """A number as written: its ``value``, whether it is written as an integer (``count``) and the ``unit`` of its
    last digit."""

    value: float
    count: bool
    unit: float
    text: str


def figures(line: str) -> list[Figure]:
    """The figures of a line of text, in order."""
    out = []
    for m in NUMBER.finditer(line):
        sign, whole, fraction, exponent = m.groups()
        digits = whole.replace(",", "") + (fraction or "")
        scale = 10.0 ** int(exponent) if exponent else 1.0
        value = float(digits) * scale * (-1.0 if sign in ("-", "−") else 1.0)
        decimals = len(fraction) - 1 if fraction else 0
        out.append(Figure(value, not fraction and not exponent, 10.0 ** -decimals * scale, m.group(0)))
    return out


def skeleton(line: str) -> str:
    """A line's words without its figures and timings (``#`` for each), whitespace collapsed; a Markdown table's
    separator row as ``|---|`` per column."""
    line = line.strip()
    if SEPARATOR.match(line) and "-" in line:
        return "|" + "---|" * (line.strip("|").count("|") + 1)
    line = TIMING.sub("in <time> s", line)
    return " ".join(NUMBER.sub("#", line).split())


def compared(line: str) -> list[Figure]:
    """The figures of a printed line that are compared (its timings left out)."""
    return figures(TIMING.sub("in <time> s", line))


def agree_with_run(page: Figure, run: Figure, tolerance: float = TOLERANCE, count: bool = True) -> bool:
    """A figure of a printed block against the run's printed one: a count (``count`` and an integer on both sides)
    exactly, else within ``tolerance`` of it or one unit of the page's last digit."""
    if count and page.count and run.count:
        return page.value == run.value
    return abs(page.value - run.value) <= max(tolerance * abs(run.value), page.unit * 1.0000001)


def rounds_to(prose: Figure, source: Figure) -> bool:
    """A figure of the prose is its source (a printed block's) rounded: within half a unit of the last digit of each
    where it has fewer digits; the same figure where it has as many (a count too)."""
    if (prose.count and source.count) or prose.unit <= source.unit * 1.0000001:  # as many digits: the same figure
        return abs(prose.value - source.value) <= 1e-9 * max(abs(source.value), 1.0)
    return abs(prose.value - source.value) <= (prose.unit + source.unit) / 2 * 1.0000001


@dataclass
class Region:
    """A printed block of a page: its first line's number, its lines (a paragraph joined into one), whether it is a
    Markdown table, its tolerance and the lines of the runnable blocks whose output it is."""

    line: int
    lines: list[str]
    table: bool
    tolerance: float
    blocks: list[int]
    counts: tuple[str, ...] | None = None


def fenced(text: str) -> list[tuple[int, int, str, str]]:
    """The fenced blocks of a Markdown text: (first line, last line, language, body), lines counted from 1."""
    out = []
    for m in FENCE.finditer(text):
        first = text[:m.start()].count("\n") + 1
        out.append((first, first + m.group(0).count("\n"), m.group(1), m.group(2)))
    return out


def runnable(body: str) -> bool:
    """A bash or python block the page runs (not one that says ``# not run:``)."""
    return not body.split("\n", 1)[0].strip().startswith("# not run:")


def regions(text: str) -> list[Region]:
    """The printed blocks of a page (``<!-- printed -->``), each with the runnable blocks whose output it is.

    Raises
    ------
    ValueError
        A marker followed by nothing it can mark (one line naming the page's line).
    """
    lines = text.split("\n")
    blocks = fenced(text)
    inside = {n for first, last, _, _ in blocks for n in range(first, last + 1)}
    run = [first for first, _, language, body in blocks if language in ("bash", "python") and runnable(body)]
    out: list[Region] = []
    previous = 0
    for number, line in enumerate(lines, 1):
        m = PRINTED.match(line.strip())
        if not m or number in inside:
            continue
        tolerance = float(m.group(1)) / 100 if m.group(1) else TOLERANCE
        counts = tuple(c.strip() for c in m.group(2).split(",")) if m.group(2) else None
        start = number + 1
        while start <= len(lines) and not lines[start - 1].strip():
            start += 1
        if start > len(lines):
            raise ValueError(f"line {number}: '<!-- printed -->' marks nothing")
        block = next((b for b in blocks if b[0] == start), None)
        if block is not None:
            body = block[3].rstrip("\n").split("\n")
            table = False
            start += 1  # its first line's number: the body's
        else:
            end = start
            while end <= len(lines) and lines[end - 1].strip():
                end += 1
            chunk = lines[start - 1:end - 1]
            table = chunk[0].lstrip().startswith("|")
            body = chunk if table else [" ".join(s.strip() for s in chunk)]
        ran = [b for b in run if previous < b < number]
        if not ran:
            ran = out[-1].blocks if out else []
        if not ran:
            raise ValueError(f"line {number}: '<!-- printed -->' follows no block that runs")
        previous = number
        if counts is not None and (not table or set(counts) - {_plain(c) for c in _cells(body[0])}):
            raise ValueError(f"line {number}: 'counts: {', '.join(counts)}' names no column of a table after it")
        out.append(Region(start, body, table, tolerance, ran, counts))
    return out


def check_printed(region: Region, output: str) -> list[str]:
    """What of a printed block the run's ``output`` (the text its blocks printed) does not hold: one line per
    problem, naming the page's line."""
    problems = []
    printed = [line for line in output.split("\n") if line.strip()]
    shapes = [skeleton(line) for line in printed]
    used: set[int] = set()
    for offset, expected in enumerate(region.lines):
        where = region.line + (offset if region.table or len(region.lines) > 1 else 0)
        if not expected.strip():
            continue
        shape = skeleton(expected)
        found = next((i for i, s in enumerate(shapes) if s == shape and i not in used), None)
        if found is None:
            problems.append(f"line {where}: not printed by the run: {expected.strip()!r}")
            continue
        used.add(found)
        for page, run, count in _pairs(region, expected, printed[found]):
            if not agree_with_run(page, run, region.tolerance, count):
                problems.append(f"line {where}: {page.text} where the run printed {run.text}: "
                                f"{printed[found].strip()!r}")
    return problems


def _pairs(region: Region, expected: str, printed: str) -> list[tuple[Figure, Figure, bool]]:
    """The figures of a page's line and of the run's line of the same words, side by side, each with whether it may
    be a count: every integer, or in a table whose counts are named only those of the columns named."""
    if region.counts is None:
        return [(a, b, True) for a, b in zip(compared(expected), compared(printed))]
    header = [_plain(c) for c in _cells(region.lines[0])]
    out = []
    for j, (a, b) in enumerate(zip(_cells(expected), _cells(printed))):
        count = j < len(header) and header[j] in region.counts
        out += [(x, y, count) for x, y in zip(compared(a), compared(b))]
    return out


def _cells(line: str) -> list[str]:
    return [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))]


def _plain(cell: str) -> str:
    return " ".join(re.sub(r"<!--.*?-->", "", cell).replace("**", "").replace("`", "").split())


def _from_tables(key: str, tables: list[Region]) -> tuple[Figure | None, str]:
    *labels, column = [_plain(p) for p in key.split("·")]
    found = []
    for table in tables:  # the tables of that column where the labels pick one row
        header = [_plain(c) for c in _cells(table.lines[0])]
        if column not in header:
            continue
        j = header.index(column)
        rows = [cells for cells in ([_plain(c) for c in _cells(row)] for row in table.lines[2:])
                if cells[:len(labels)] == labels and j < len(cells)]
        if len(rows) == 1:
            found.append((table.line, rows[0][j]))
    if len(found) != 1:
        return None, (f"{len(found)} printed tables of the page have one row {' · '.join(labels)!r} and a column "
                      f"{column!r} (one is needed)")
    numbers = figures(found[0][1])
    if not numbers:
        return None, f"the cell {key!r} holds no figure: {found[0][1]!r}"
    return numbers[0], ""


def _from_phrase(phrase: str, texts: list[Region]) -> tuple[Figure | None, str]:
    holding = {line for region in texts for line in region.lines if phrase in line}
    if len(holding) != 1:
        return None, f"{len(holding)} lines of the page's printed blocks hold {phrase!r} (one is needed)"
    after = figures(holding.pop().split(phrase, 1)[1])
    if not after:
        return None, f"no figure after {phrase!r} in the printed line"
    return after[0], ""


def _from_json(key: str, folder: Path) -> tuple[float | None, str]:
    path, _, dotted = key.partition(" ")
    file = folder / path
    if not file.is_file():
        return None, f"{path} was not written by the page's blocks"
    value = json.loads(file.read_text())
    for part in re.findall(r"[^.\[\]]+|\[\d+\]", dotted.strip()):
        try:
            value = value[int(part[1:-1])] if part.startswith("[") else value[part]
        except (KeyError, IndexError, TypeError):
            return None, f"{path} has no {dotted.strip()!r}"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None, f"{path}'s {dotted.strip()!r} is not a number: {value!r}"
    return float(value), ""


def prose_figures(text: str) -> list[tuple[int, Figure | None, str]]:
    """The prose's marked figures: (line, the figure before the marker or None, the key)."""
    out = []
    blocks = fenced(text)
    inside = {n for first, last, _, _ in blocks for n in range(first, last + 1)}
    for number, line in enumerate(text.split("\n"), 1):
        if number in inside:
            continue
        line = re.sub(r"`[^`]*`", lambda code: " " * len(code.group(0)), line)  # a marker quoted is none
        start = 0
        for m in FIGURE.finditer(line):
            before = line[start:m.start()]
            start = m.end()
            found = None
            for candidate in NUMBER.finditer(before):
                if BETWEEN.fullmatch(before[candidate.end():]):
                    found = figures(candidate.group(0))[0]
            out.append((number, found, m.group(1)))
    return out


def check_prose(text: str, folder: Path | None = None) -> list[str]:
    """The prose's marked figures against their keys: the page's printed blocks always, the files the run wrote
    where ``folder`` (where the page's blocks ran) is given. One line per problem, naming the page's line."""
    problems = []
    try:
        printed = regions(text)
    except ValueError as exc:
        return [str(exc)]
    tables = [r for r in printed if r.table]
    texts = [r for r in printed if not r.table]
    for number, figure, key in prose_figures(text):
        if figure is None:
            problems.append(f"line {number}: no figure just before '<!-- figure: {key} -->'")
            continue
        first = key.split(" ", 1)[0]
        if first.endswith(".json"):
            if folder is None:
                continue
            own = re.search(r"\s+±\s*(\d+(?:\.\d+)?)\s*%$", key)
            tolerance = float(own.group(1)) / 100 if own else TOLERANCE
            value, why = _from_json(key[:own.start()] if own else key, folder)
            if value is None:
                problems.append(f"line {number}: {why}")
            elif not (figure.value == value if figure.count and value.is_integer() else
                      abs(figure.value - value) <= max(tolerance * abs(value), figure.unit / 2 * 1.0000001)):
                problems.append(f"line {number}: {figure.text} where the run wrote {value:.6g} ({key})")
            continue
        if key.startswith('"') and key.endswith('"') and len(key) > 2:
            source, why = _from_phrase(key[1:-1], texts)
        elif "·" in key:
            source, why = _from_tables(key, tables)
        else:
            source, why = None, f"the key {key!r} is neither 'ROW · COLUMN', '\"PHRASE\"' nor 'FILE.json KEY'"
        if source is None:
            problems.append(f"line {number}: {why}")
        elif not rounds_to(figure, source):
            problems.append(f"line {number}: {figure.text} where the page's printed block has {source.text} ({key})")
    return problems


def check_page(text: str, outputs: dict[int, str], folder: Path | None) -> list[str]:
    """A page's marked figures against its run: ``outputs`` maps each runnable block's first line to what it printed
    (stdout and stderr), ``folder`` is where the blocks ran (None: the files the blocks wrote are not checked). One
    line per problem, naming the page's line."""
    try:
        printed = regions(text)
    except ValueError as exc:
        return [str(exc)]
    problems = []
    for region in printed:
        missing = [b for b in region.blocks if b not in outputs]
        if missing:
            problems.append(f"line {region.line}: the blocks at lines {missing} did not run")
            continue
        problems += check_printed(region, "\n".join(outputs[b] for b in region.blocks))
    return problems + check_prose(text, folder)


def marked(text: str) -> bool:
    """Whether a page marks any figure."""
    return bool(regions(text) or prose_figures(text))


__all__ = ["TOLERANCE", "Figure", "Region", "agree_with_run", "check_page", "check_printed", "check_prose",
           "figures", "marked", "prose_figures", "regions", "rounds_to", "skeleton"]
