"""The yardsticks of the campaign benchmark's replicate-step: one Extended Kalman Filter predict + update of the
paper's problem, in FilterPy and in plain C.

The problem (:data:`BEACONS`, :func:`problem`): six states ``[posX, velX, posY, velY, posZ, velZ]``, a constant-
velocity transition, the ranges to four beacons and the depth, measured every step. FilterPy's
``ExtendedKalmanFilter`` steps it in numpy, whose small-matrix overhead moves from machine to machine;
``ekf_floor.c`` steps it in plain C (a joint update with a Cholesky solve, built here with
:func:`sblsim.fmus.compiler.find_compiler` at ``-O2`` without vectorization), the compiled floor a replicate-step
of sblsim is measured against. Before the C step is timed, :func:`check_floor` asserts that it computes FilterPy's
step: the state and covariance after every one of :data:`CHECK_STEPS` steps agree to :data:`TOLERANCE`.
"""

from __future__ import annotations

import ctypes
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

from sblsim.fmus.compiler import find_compiler

SOURCE = Path(__file__).resolve().parent / "ekf_floor.c"
#: How the floor is compiled: optimized, without vectorization (no SIMD), IEEE arithmetic (no fused multiply-add).
FLAGS = ("-O2", "-fno-tree-vectorize", "-fno-tree-slp-vectorize", "-ffp-contract=off", "-std=c99", "-fPIC",
         "-shared")
#: The beacons [m] (North, East, Down), the time step [s], the measurement variances (ranges, depth) [m²].
BEACONS = np.array([[3.0, 0, 1], [0, 3.0, 1], [-3.0, 0, 1], [0, -3.0, 1]])
DT, RANGE_VARIANCE, DEPTH_VARIANCE = 0.1, 0.01, 1e-4
#: The largest difference allowed between the C step's state and covariance and FilterPy's, and over how many steps.
TOLERANCE, CHECK_STEPS = 1e-12, 20

_DOUBLES = ctypes.POINTER(ctypes.c_double)


def hx(x: np.ndarray) -> np.ndarray:
    """The measurements at the state ``x`` (6, 1): the four ranges and the depth (5, 1)."""
    p = x[[0, 2, 4], 0]
    return np.append(np.linalg.norm(p - BEACONS, axis=1), x[4, 0]).reshape(-1, 1)


def jacobian(x: np.ndarray) -> np.ndarray:
    """The measurements' Jacobian at ``x`` (5, 6)."""
    p = x[[0, 2, 4], 0]
    H = np.zeros((5, 6))
    d = p - BEACONS
    H[:4][:, [0, 2, 4]] = d / np.linalg.norm(d, axis=1)[:, None]
    H[4, 4] = 1.0
    return H


def problem() -> dict[str, np.ndarray]:
    """The initial state ``x`` (6, 1) and covariance ``P``, the transition ``F``, ``Q``, ``R`` and the measurement
    ``z`` (5, 1) every step is given (the ranges and depth of the initial state, all 1 cm long)."""
    x = np.array([[15.0], [0.0], [0.0], [0.5], [5.0], [0.0]])
    return {"x": x, "P": np.eye(6), "F": np.eye(6) + np.diag([DT, 0, DT, 0, DT], 1), "Q": np.eye(6) * 1e-4,
            "R": np.diag([RANGE_VARIANCE] * 4 + [DEPTH_VARIANCE]), "z": hx(x) + 0.01}


def filterpy_filter(values: dict[str, np.ndarray] | None = None):
    """FilterPy's ``ExtendedKalmanFilter`` set to the problem (default :func:`problem`) and its step
    ``step() -> (x, P)``."""
    from filterpy.kalman import ExtendedKalmanFilter

    values = values or problem()
    ekf = ExtendedKalmanFilter(dim_x=6, dim_z=5)
    ekf.x, ekf.P, ekf.F, ekf.Q = values["x"].copy(), values["P"].copy(), values["F"], values["Q"]

    def step() -> tuple[np.ndarray, np.ndarray]:
        ekf.predict()
        ekf.update(values["z"], jacobian, hx, R=values["R"])
        return ekf.x, ekf.P

    return step


def filterpy_step(repeat: int = 1000, rounds: int = 7) -> float:
    """Seconds of one FilterPy predict + update (the best of ``rounds`` rounds of ``repeat`` steps, after 200)."""
    step = filterpy_filter()
    for _ in range(200):
        step()
    best = float("inf")
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(repeat):
            step()
        best = min(best, (time.perf_counter() - start) / repeat)
    return best


def build(directory: Path) -> ctypes.CDLL:
    """``ekf_floor.c`` compiled with :data:`FLAGS` by the project's compiler (the system's, else zig) into
    ``directory``, loaded.

    Raises
    ------
    sblsim.models.errors.CompileError
        If no compiler is found.
    subprocess.CalledProcessError
        If the compilation fails.
    """
    compiler = find_compiler()
    library = Path(directory) / "ekf_floor.so"
    subprocess.run([*compiler.command, *FLAGS, str(SOURCE), "-o", str(library), "-lm"], check=True,
                   capture_output=True)
    lib = ctypes.CDLL(str(library))
    for name in ("ekf_step", "ekf_steps"):
        getattr(lib, name).restype = ctypes.c_int
    return lib


def _pointer(array: np.ndarray):
    return array.ctypes.data_as(_DOUBLES)


def c_filter(lib: ctypes.CDLL, values: dict[str, np.ndarray] | None = None) -> Callable[[], tuple]:
    """The C filter set to the problem (default :func:`problem`) and its step ``step() -> (x, P)``."""
    values = values or problem()
    x, P = np.ascontiguousarray(values["x"].ravel()), np.ascontiguousarray(values["P"], dtype=float)
    fixed = [np.ascontiguousarray(values[k], dtype=float) for k in ("F", "Q", "R")]
    fixed += [np.ascontiguousarray(BEACONS), np.ascontiguousarray(values["z"].ravel())]

    def step() -> tuple[np.ndarray, np.ndarray]:
        if lib.ekf_step(_pointer(x), _pointer(P), *map(_pointer, fixed)):
            raise ArithmeticError("the C EKF step failed: S is not positive definite")
        return x.reshape(-1, 1).copy(), P.copy()

    return step


def difference(first: Callable[[], tuple], second: Callable[[], tuple], steps: int = CHECK_STEPS) -> float:
    """The largest difference between two filters' states and covariances over ``steps`` steps of each."""
    worst = 0.0
    for _ in range(steps):
        (x1, P1), (x2, P2) = first(), second()
        worst = max(worst, float(np.max(np.abs(x1 - x2))), float(np.max(np.abs(P1 - P2))))
    return worst


def check_floor(lib: ctypes.CDLL, values: dict[str, np.ndarray] | None = None) -> float:
    """Check that the C step computes FilterPy's on the problem: the C filter given ``values`` (default
    :func:`problem`) against FilterPy's given the problem. Returns the largest difference.

    Raises
    ------
    AssertionError
        If it exceeds :data:`TOLERANCE` (or a step fails).
    """
    worst = difference(c_filter(lib, values), filterpy_filter())
    assert worst <= TOLERANCE, f"the C EKF step differs from FilterPy's by {worst:.3g} (> {TOLERANCE:g})"
    return worst


def c_step(lib: ctypes.CDLL, filters: int = 800, steps: int = 100, rounds: int = 7) -> float:
    """Seconds of one C predict + update: ``filters`` filters stepped ``steps`` times in one call (a step of each
    after another, as a batch's replicates), the best of ``rounds`` calls."""
    values = problem()
    xs = np.ascontiguousarray(np.tile(values["x"].ravel(), (filters, 1)))
    Ps = np.ascontiguousarray(np.tile(values["P"], (filters, 1, 1)))
    fixed = [np.ascontiguousarray(values[k], dtype=float) for k in ("F", "Q", "R")]
    fixed += [np.ascontiguousarray(BEACONS), np.ascontiguousarray(values["z"].ravel())]
    best = float("inf")
    for k in range(rounds + 1):  # the first call (not counted) converges the filters and warms the caches
        start = time.perf_counter()
        if lib.ekf_steps(filters, steps, _pointer(xs), _pointer(Ps), *map(_pointer, fixed)):
            raise ArithmeticError("the C EKF step failed: S is not positive definite")
        best = min(best, time.perf_counter() - start) if k else best
    return best / (filters * steps)


def floor_step() -> tuple[float, float, str]:
    """The C step built and checked against FilterPy here (:func:`check_floor`), then timed (:func:`c_step`):
    its seconds, the largest difference from FilterPy's and the compiler that built it."""
    with tempfile.TemporaryDirectory(prefix="sblsim_floor_") as tmp:
        lib = build(Path(tmp))
        worst = check_floor(lib)
        return c_step(lib), worst, find_compiler().describe()
