"""Range measurement model and its Jacobian, derived symbolically with casadi.

``h(x, b) = ‖p − b‖`` with ``p = (x[0], x[2], x[4])`` taken from the EKF state
``x = [posX, velX, posY, velY, posZ, velZ]`` and ``b`` a broadcast beacon
position. The Jacobian ``H = ∂h/∂x`` (1 × 6) is never written by hand: casadi
differentiates the expression. The casadi function is then translated,
instruction by instruction, into one vectorized numpy function
(:func:`numpy_function`), which evaluates all beacon-replicate pairs of a
batch in a few array operations; the tests check the translation against
casadi's own evaluation and against finite differences.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Eqs. for the
EKF measurement model. Andersson, Gillis, Horn, Rawlings, Diehl, "CasADi: a
software framework for nonlinear optimization and optimal control",
Math. Prog. Comp. 11, 2019.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Callable

import casadi as ca
import numpy as np

STATE_SIZE = 6
POSITION_INDEX = [0, 2, 4]

# casadi SX operation code -> numpy expression of the operands a, b (or a constant).
_UNARY = {
    ca.OP_ASSIGN: "{a}", ca.OP_NEG: "-{a}", ca.OP_EXP: "np.exp({a})", ca.OP_LOG: "np.log({a})",
    ca.OP_SQRT: "np.sqrt({a})", ca.OP_SQ: "{a} * {a}", ca.OP_TWICE: "2.0 * {a}", ca.OP_SIN: "np.sin({a})",
    ca.OP_COS: "np.cos({a})", ca.OP_TAN: "np.tan({a})", ca.OP_ASIN: "np.arcsin({a})",
    ca.OP_ACOS: "np.arccos({a})", ca.OP_ATAN: "np.arctan({a})", ca.OP_FABS: "np.abs({a})",
    ca.OP_SIGN: "np.sign({a})", ca.OP_INV: "1.0 / {a}", ca.OP_SINH: "np.sinh({a})",
    ca.OP_COSH: "np.cosh({a})", ca.OP_TANH: "np.tanh({a})", ca.OP_FLOOR: "np.floor({a})",
    ca.OP_CEIL: "np.ceil({a})",
}
_BINARY = {
    ca.OP_ADD: "{a} + {b}", ca.OP_SUB: "{a} - {b}", ca.OP_MUL: "{a} * {b}", ca.OP_DIV: "{a} / {b}",
    ca.OP_POW: "{a} ** {b}", ca.OP_CONSTPOW: "{a} ** {b}", ca.OP_FMIN: "np.minimum({a}, {b})",
    ca.OP_FMAX: "np.maximum({a}, {b})", ca.OP_ATAN2: "np.arctan2({a}, {b})", ca.OP_HYPOT: "np.hypot({a}, {b})",
    ca.OP_COPYSIGN: "np.copysign({a}, {b})", ca.OP_FMOD: "np.fmod({a}, {b})",
}


def numpy_function(function: ca.Function) -> Callable[..., list[np.ndarray]]:
    """Translate a casadi SX function into a vectorized numpy function.

    The generated function replays casadi's instruction list (the same
    operations in the same order) on numpy arrays, so it evaluates any
    number of points at once by broadcasting.

    Parameters
    ----------
    function : casadi.Function
        An SX function whose inputs are dense column vectors.

    Returns
    -------
    callable
        ``f(*inputs) -> [outputs]``: input ``j`` is a sequence of
        ``function.size1_in(j)`` arrays (broadcastable to one shape S);
        output ``k`` is an array of shape ``(function.size1_out(k), *S')``
        with zeros at the structural zeros, S' the broadcast shape of the
        inputs it depends on (``()`` for a constant output).

    Raises
    ------
    ValueError
        If an input is not a dense column vector, an output is not a column
        vector, or an operation has no numpy counterpart.
    """
    for j in range(function.n_in()):
        sp = function.sparsity_in(j)
        if sp.size2() != 1 or not sp.is_dense():
            raise ValueError(f"{function.name()}: input {j} is not a dense column vector")
    for k in range(function.n_out()):
        if function.sparsity_out(k).size2() != 1:
            raise ValueError(f"{function.name()}: output {k} is not a column vector")
    lines = [f"def {function.name()}({', '.join(f'in{j}' for j in range(function.n_in()))}):"]
    names = [f"in{j}" for j in range(function.n_in())]
    outputs = {}
    for k in range(function.n_instructions()):
        op, i, o = function.instruction_id(k), function.instruction_input(k), function.instruction_output(k)
        if op == ca.OP_INPUT:
            expr = f"{names[i[0]]}[{i[1]}]"
        elif op == ca.OP_OUTPUT:  # copy now: casadi may re-use the work slot afterwards
            outputs[(o[0], o[1])] = f"out{o[0]}_{o[1]}"
            lines.append(f"    out{o[0]}_{o[1]} = w{i[0]}")
            continue
        elif op == ca.OP_CONST:
            expr = f"float('{float(function.instruction_constant(k))!r}')"
        elif op in _UNARY:
            expr = _UNARY[op].format(a=f"w{i[0]}")
        elif op in _BINARY:
            expr = _BINARY[op].format(a=f"w{i[0]}", b=f"w{i[1]}")
        else:
            raise ValueError(f"{function.name()}: casadi operation {op} has no numpy translation")
        lines.append(f"    w{o[0]} = {expr}")
    # outputs: the nonzeros stacked into dense rows, zeros elsewhere
    result = []
    for k in range(function.n_out()):
        sp = function.sparsity_out(k)
        dense = ["0.0"] * sp.size1()
        for nz, row in enumerate(sp.row()):
            dense[row] = outputs.get((k, nz), "0.0")
        result.append(f"_stack([{', '.join(dense)}])")
    lines.append(f"    return [{', '.join(result)}]")
    namespace = {"np": np, "_stack": _stack}
    exec(compile("\n".join(lines), f"<casadi {function.name()}>", "exec"), namespace)  # noqa: S102
    return namespace[function.name()]


def _stack(values: list) -> np.ndarray:
    """Stack scalars and arrays along a new first axis, broadcasting scalars."""
    arrays = np.broadcast_arrays(*[np.asarray(v, dtype=float) for v in values])
    return np.stack(arrays)


def _range_model(name: str, size: int, position_index: list[int]) -> ca.Function:
    """casadi Function ``(x[size], b[3]) -> (‖p(x) − b‖, ∂h/∂x [size])`` with ``p = x[position_index]``."""
    x = ca.SX.sym("x", size)
    b = ca.SX.sym("b", 3)
    p = ca.vertcat(*[x[i] for i in position_index])
    h = ca.norm_2(p - b)
    return ca.Function(name, [x, b], [h, ca.jacobian(h, x).T], ["x", "b"], ["h", "H"])


@lru_cache(maxsize=1)
def range_function() -> ca.Function:
    """casadi Function ``(x[6], b[3]) -> (h, Hᵀ[6])`` of one range, x the EKF state."""
    return _range_model("range_model", STATE_SIZE, POSITION_INDEX)


@lru_cache(maxsize=1)
def position_range_function() -> ca.Function:
    """casadi Function ``(p[3], b[3]) -> (h, ∂h/∂p [3])`` of one range, p a position."""
    return _range_model("position_range_model", 3, [0, 1, 2])


@lru_cache(maxsize=1)
def range_numpy() -> Callable[..., list[np.ndarray]]:
    """:func:`range_function` translated by :func:`numpy_function`."""
    return numpy_function(range_function())


@lru_cache(maxsize=1)
def position_range_numpy() -> Callable[..., list[np.ndarray]]:
    """:func:`position_range_function` translated by :func:`numpy_function`.

    Called with components first: ``p`` of shape (3, B, 1) and ``b`` of
    shape (3, B, n) give ``h`` (1, B, n) and ``∂h/∂p`` (3, B, n).
    """
    return numpy_function(position_range_function())


def range_and_jacobian(states: np.ndarray, beacons: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Predicted ranges and their Jacobians for a batch of states and beacons.

    Parameters
    ----------
    states : ndarray, shape (B, 6)
        EKF states ``[posX, velX, posY, velY, posZ, velZ]`` [m, m/s].
    beacons : ndarray, shape (B, n, 3)
        Broadcast beacon positions [m].

    Returns
    -------
    h : ndarray, shape (B, n)
        Predicted ranges ``‖p − b‖`` [m].
    H : ndarray, shape (B, n, 6)
        Jacobians ``∂h/∂x`` [1, 0 for the velocity columns].
    """
    x = np.moveaxis(np.asarray(states, dtype=float), -1, 0)[:, :, None]  # (6, B, 1)
    b = np.moveaxis(np.asarray(beacons, dtype=float), -1, 0)  # (3, B, n)
    h, jac = range_numpy()(x, b)
    return h[0], np.moveaxis(jac, 0, -1)
