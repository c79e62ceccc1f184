"""casadi expression helpers shared by the component models: sample clocks, padded tables,
branch selection and table lookups.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

import functools
import time
from typing import Any, Callable, Sequence

import casadi as ca
import numpy as np

from sblsim.models.interrupts import check

#: An index past every row: :func:`put_row` at it writes nothing.
NO_ROW = 1e9


def sample_due(index, start, period, t, h):
    """Guard of a periodic sample: the next sample ``start + (index + 1)·period`` has been reached by
    the end ``t + h`` of the step (to within 1e-6 periods, so that a host's rounded communication
    points neither miss nor add a sample) [s]."""
    return start + (index + 1.0) * period <= t + h + 1e-6 * period


def padded_rows(count, columns: Sequence[Any], gap: float) -> tuple[list[Any], list[Any]]:
    """A table's rows padded for interpolation: the used rows, then rows that keep the grid increasing.

    Rows ``k < count`` are kept; a row ``k ≥ count`` repeats the last used row,
    its first column continuing ``last + gap + (k − count)``. Built with
    casadi's ``mapaccum`` (one loop in the generated C).

    Parameters
    ----------
    count : casadi.MX
        Rows in use.
    columns : sequence of casadi.MX, each (N, 1)
        The columns.
    gap : float
        Step from the last used value of the first column to the first padding row.

    Returns
    -------
    padded : list of casadi.MX, each (N, 1)
    last : list of casadi.MX
        The last used row (zeros if ``count`` is 0).
    """
    m, N = len(columns), int(columns[0].numel())
    acc = ca.SX.sym("acc", 2 + m)
    row = [ca.SX.sym(f"c{j}") for j in range(m)]
    k, n, last = acc[0], acc[1], acc[2:]
    used = k < n
    first = ca.if_else(used, row[0], last[0] + gap + (k - n))
    out = [first] + [ca.if_else(used, row[j], last[j]) for j in range(1, m)]
    kept = ca.vertcat(*[ca.if_else(used, row[j], last[j]) for j in range(m)])
    pad = ca.Function("sblsim_pad_row", [acc] + row, [ca.vertcat(k + 1, n, kept)] + out).mapaccum("sblsim_pad", N)
    result = pad(ca.vertcat(0, count, ca.MX.zeros(m)), *[ca.reshape(c, 1, N) for c in columns])
    final = result[0][:, N - 1]
    return [ca.reshape(r, N, 1) for r in result[1:]], [final[2 + j] for j in range(m)]


def cumulative_sum(values: Any) -> Any:
    """Running sum of an (N, 1) casadi.MX vector (``mapaccum``), starting with the first value."""
    N = int(values.numel())
    acc, v = ca.SX.sym("acc"), ca.SX.sym("v")
    total = ca.Function("sblsim_add", [acc, v], [acc + v, acc + v]).mapaccum("sblsim_cumsum", N)
    return ca.reshape(total(0, ca.reshape(values, 1, N))[1], N, 1)


def switch(name: str, branches: Sequence[ca.Function]) -> ca.Function:
    """``f(index, *args) = branches[index](*args)``, only that branch evaluated in the generated C.

    A casadi ``Switch`` called through a never-inlined wrapper: an SX
    expression that calls it holds one call, and the C it generates runs the
    selected branch alone (an ``if_else`` of the branches would evaluate them
    all). ``index`` is rounded toward zero; outside ``[0, n)`` it takes the
    last branch. The branches share one signature.
    """
    first = branches[0]
    switch_f = ca.Function.conditional(f"{name}_switch", list(branches[:-1]), branches[-1])
    index = ca.MX.sym("index")
    args = [ca.MX.sym(first.name_in(k), first.sparsity_in(k)) for k in range(first.n_in())]
    return ca.Function(name, [index, *args], switch_f.call([index, *args]), ["index", *first.name_in()],
                       first.name_out(), {"never_inline": True})


def only_where(name: str, condition: ca.SX, build: Callable[..., ca.SX], *args: ca.SX) -> ca.SX:
    """``build(*args)`` where ``condition`` is 1, an exact 0 where it is 0: the generated C computes it only where
    ``condition`` holds, for a value read only then (an ``if_else`` or a logical ``and`` computes its operands
    every time).

    ``build`` is given a symbol for each of ``args`` (their values computed outside, once) and returns an SX;
    whatever else it reads (the calling function's own symbols: states, inputs, parameters) is passed to it as it
    is. Its result is the branch of a :func:`switch`: the same operations on the same values as ``build(*args)``,
    so the same number bit for bit where it is computed.
    """
    symbols = [ca.SX.sym(f"{name}_{k}", *a.shape) for k, a in enumerate(args)]
    value = build(*symbols)
    given = ca.symvar(ca.vertcat(*[ca.vec(s) for s in symbols])) if symbols else []
    free = [s for s in ca.symvar(value) if not any(ca.is_equal(s, g) for g in given)]
    passed = ca.vertcat(*free) if free else ca.SX(0, 1)
    computed = ca.Function(f"{name}_computed", [*symbols, passed], [value])
    skipped = ca.Function(f"{name}_skipped", [*symbols, passed], [ca.SX.zeros(value.shape)])
    return switch(name, [skipped, computed])(condition, *args, passed)


def select(index: ca.SX, rows: Sequence[ca.SX]) -> ca.SX:
    """``rows[index]`` for a symbolic integer-valued ``index`` (zero if out of range).

    Sums ``if_else(index == k, rows[k], 0)``: exact, since the other
    terms are exact zeros. Every row is computed; for costly alternatives use
    :func:`switch`.
    """
    total = 0
    for k, row in enumerate(rows):
        total = total + ca.if_else(index == k, row, 0)
    return total


@functools.lru_cache(maxsize=None)
def _row_functions(rows: int, columns: int) -> tuple[ca.Function, ca.Function]:
    """The never-inlined ``put`` and ``get`` of one row of a (rows, columns) column-major table."""
    table, index, row = ca.MX.sym("table", rows * columns), ca.MX.sym("index"), ca.MX.sym("row", columns)
    places = index + ca.DM(list(range(0, rows * columns, rows)))
    written = ca.MX(table)
    written.set_nz(row, False, places)
    options = {"never_inline": True}
    return (ca.Function(f"sblsim_put_row_{rows}x{columns}", [table, index, row], [written], options),
            ca.Function(f"sblsim_get_row_{rows}x{columns}", [table, index], [table.get_nz(False, places)], options))


def put_row(table: Sequence[ca.SX], index: ca.SX, row: Sequence[Any]) -> list[ca.SX]:
    """Columns ``table`` (each of the same length) with row ``index`` replaced by ``row``.

    One call of a generated function that writes the row in place (a parametric index): no ``if_else`` per
    element. ``index`` at or past the row count (:data:`NO_ROW`) writes nothing. Returns the new columns.
    """
    rows, columns = int(table[0].numel()), len(table)
    put = _row_functions(rows, columns)[0]
    written = put(ca.vertcat(*table), index, ca.vertcat(*row))
    return [written[j * rows:(j + 1) * rows] for j in range(columns)]


def get_row(table: Sequence[ca.SX], index: ca.SX) -> list[ca.SX]:
    """Row ``index`` (in range) of columns ``table``: one element per column, read at a parametric index."""
    rows, columns = int(table[0].numel()), len(table)
    row = _row_functions(rows, columns)[1](ca.vertcat(*table), index)
    return [row[j] for j in range(columns)]


def lookup(index: ca.SX, values: Sequence[float]) -> ca.SX:
    """A constant table indexed by a symbolic integer (zero if out of range)."""
    return select(index, [float(v) for v in values])


def _value(x: Any) -> Any:
    """A float for a 1×1 numeric casadi result (``ca.if_else`` of floats gives a ``DM``), else ``x``."""
    if isinstance(x, ca.DM) and x.numel() == 1:
        return float(x)
    return x


__all__ = ["cumulative_sum", "get_row", "lookup", "NO_ROW", "only_where", "padded_rows", "put_row", "sample_due",
           "select", "switch"]


#: How long one call of :func:`map_in_chunks` may take [s]: Ctrl-C waits for the call under way.
CHUNK_SECONDS = 0.1


def map_in_chunks(function: ca.Function, columns: Sequence[Any], shared: Sequence[Any] = (),
                  seconds: float = CHUNK_SECONDS) -> list[np.ndarray]:
    """``function`` evaluated at every column of ``columns``, as its map over them all, in calls of about
    ``seconds`` each.

    A map over many points (a site's eigenrays over a grid of a million points) is minutes of compiled code in
    one call, during which Python handles no signal: a user's Ctrl-C or SIGTERM would wait for its end. Cut into
    chunks, the signal is handled between two of them (and a stop whose exception a call lost is checked there:
    :func:`sblsim.models.interrupts.check`). The chunk's width is adapted to the time the last one
    took (a power of two, from 16 columns); each column is evaluated alone, so the numbers are those of one map.

    Parameters
    ----------
    function : casadi.Function
        Its inputs: first one row per entry of ``columns``, then ``shared`` (the same for every column).
    columns : sequence of array_like, each shape (n,)
        The mapped inputs.
    shared : sequence
        The inputs every column shares.
    seconds : float
        The time one call should take [s].

    Returns
    -------
    list of numpy.ndarray, each shape (rows, n)
        The function's outputs, one column per point.
    """
    columns = [np.asarray(c, dtype=float).reshape(-1) for c in columns]
    n = len(columns[0]) if columns else 0
    maps: dict[int, ca.Function] = {}
    parts: list[list[np.ndarray]] = []
    start, width = 0, 16
    while start < n:
        k = min(width, n - start)
        mapped = maps.get(k) or maps.setdefault(k, function.map(k))
        began = time.perf_counter()
        out = mapped(*(c[None, start:start + k] for c in columns), *shared)
        check()  # a stop whose exception the call lost: the next piece not begun
        took = time.perf_counter() - began
        parts.append([np.asarray(o).reshape(-1, k) for o in (out if isinstance(out, (list, tuple)) else [out])])
        start += k
        if k == width:  # the next width: the power of two nearest the target's share
            width = int(2 ** np.clip(np.round(np.log2(max(k * seconds / max(took, 1e-9), 1.0))), 0, 20))
    if not parts:
        return [np.zeros((function.size1_out(j), 0)) for j in range(function.n_out())]
    return [np.concatenate([part[j] for part in parts], axis=1) for j in range(len(parts[0]))]
