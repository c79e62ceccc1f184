"""The compiled passes over recorded runs: the per-run metrics (and the position PCRB) of a batch
(``fmus/c/sblsim_metrics.c``) and a system's own PCRB (``fmus/c/sblsim_system_bound.c``), called in the local
engine's library of no model (:func:`sblsim.fmus.native.load`).
"""

from __future__ import annotations

import ctypes

import numpy as np

from sblsim.fmus.native import NO_MODELS, load
from sblsim.models.systems import interface_system


def metrics_sizes(n_beacons: int = 4) -> tuple[int, int, int]:
    """The compiled metrics pass's column, metric and per-run bound input counts (``sblsim_contract.h``)."""
    sizes = (ctypes.c_int * 3)()
    load(n_beacons, NO_MODELS).sblsim_metrics_sizes(sizes)
    return tuple(sizes)


def run_metrics(columns, fixed: np.ndarray, arms: np.ndarray, limits: tuple[float, float, float, float],
                with_bound: bool = False, n_beacons: int = 4) -> tuple[np.ndarray, np.ndarray | None]:
    """The per-run metrics of :mod:`sblsim.orchestrator.cosim.metrics`, compiled (``fmus/c/sblsim_metrics.c``).

    Parameters
    ----------
    columns : sequence of ndarray, shape (N, B) each
        The recorded outputs in the order of :data:`sblsim.orchestrator.cosim.metrics.METRIC_INPUTS`, as floats; any
        step stride, replicates contiguous (a column of the master's record array is used in place).
    fixed : ndarray, shape (B, len(FIXED))
        The bound's per-run inputs (:data:`sblsim.models.bound.FIXED`).
    arms : ndarray, shape (B, n_beacons, 3)
        Each run's beacon lever arms in NED [m].
    limits : (float, float, float, float)
        χ²₃(0.95), the divergence distance [m] and ratio, and the received packets in a row the gate rejects when
        the receiver has lost the diver.
    with_bound : bool
        Also return the position PCRB at every step.

    Returns
    -------
    metrics : ndarray, shape (B, len(RUN_METRICS))
        :data:`sblsim.orchestrator.cosim.metrics.RUN_METRICS` in order (``diverged`` 0 or 1).
    bound : ndarray, shape (N, B), or None
        ``sqrt(trace)`` of the position PCRB [m].

    Raises
    ------
    ValueError
        If the arrays do not fit together.
    """
    lib = load(n_beacons, NO_MODELS)
    n_columns, n_metrics, n_fixed = metrics_sizes(n_beacons)
    n, b = columns[0].shape
    views = [c if c.dtype == np.float64 and c.strides[1] == 8 else np.ascontiguousarray(c, dtype=float)
             for c in columns]
    if len(views) != n_columns or any(c.shape != (n, b) for c in views):
        raise ValueError(f"run_metrics: {n_columns} columns of the shape (N, B) are needed")
    fixed = np.ascontiguousarray(fixed, dtype=float)
    arms = np.ascontiguousarray(arms, dtype=float)
    if fixed.shape != (b, n_fixed) or arms.shape != (b, n_beacons, 3):
        raise ValueError(f"run_metrics: fixed {fixed.shape} and arms {arms.shape} do not fit {b} runs")
    pointers = (ctypes.c_void_p * len(views))(*[c.ctypes.data for c in views])
    strides = (ctypes.c_longlong * len(views))(*[c.strides[0] // 8 for c in views])
    out = np.empty((b, n_metrics))
    bound = np.empty((n, b)) if with_bound else None
    limit = np.asarray(limits, dtype=float)
    if lib.sblsim_run_metrics(n, b, pointers, strides, n_beacons, fixed.ctypes.data, arms.ctypes.data,
                                          limit.ctypes.data, out.ctypes.data,
                                          None if bound is None else bound.ctypes.data):
        raise MemoryError("run_metrics: out of memory")
    return out, bound


def system_bound_sizes(n_beacons: int) -> tuple[int, int, int]:
    """The sizes the library of an interface with a system's own bound was built with: (per-run inputs, per-step
    inputs, entries of the bound)."""
    sizes = (ctypes.c_int * 3)()
    load(n_beacons, NO_MODELS).sblsim_system_bound_sizes(sizes)
    return int(sizes[0]), int(sizes[1]), int(sizes[2])


def system_pcrb(n_beacons: int, fixed: np.ndarray, steps: np.ndarray, lane_steps: np.ndarray | None = None,
                lane_new: np.ndarray | None = None) -> np.ndarray:
    """The PCRB of the system of the interface of ``n_beacons`` compiled (its
    :meth:`~sblsim.models.systems.System.bound_function` stepped by ``fmus/c/sblsim_system_bound.c``, in that
    interface's library): the position PCRB of B runs (USBL: :func:`sblsim.models.systems.usbl_bound.pcrb`).

    Parameters
    ----------
    n_beacons : int
        The interface (1: USBL).
    fixed, steps : ndarray, shapes (B, len(bound_fixed)) and (N, B, len(bound_steps))
        The system's per-run and per-step inputs (USBL: :func:`sblsim.models.systems.usbl_bound.pcrb_inputs`).
    lane_steps, lane_new : ndarray, shapes (L, N, B, len(bound_steps)) and (L, N, B), optional
        The later lanes of a delivery: each lane's per-step inputs (as ``steps``, from its packet) and where it holds
        a new packet (1); each new one is a step of the bound after the step's own, in lane order, with no time
        between them (``dt`` 0). None: no packet on a later lane.

    Returns
    -------
    ndarray, shape (N, B)
        ``sqrt(trace)`` of the position PCRB at each step [m].

    Raises
    ------
    ValueError
        If the interface's system has no bound of its own, or the arrays do not fit together.
    """
    system = interface_system(n_beacons)
    if not system.bound_fixed:
        raise ValueError(f"system_pcrb: the {system.name} interface of {n_beacons} has no bound of its own")
    fixed = np.ascontiguousarray(fixed, dtype=float)
    steps = np.ascontiguousarray(steps, dtype=float)
    n, b = steps.shape[:2]
    if fixed.shape != (b, len(system.bound_fixed)) or steps.shape != (n, b, len(system.bound_steps)):
        raise ValueError(f"system_pcrb: fixed {fixed.shape} and steps {steps.shape} do not fit together")
    if lane_steps is None:
        lane_steps, lane_new = np.zeros((0, n, b, steps.shape[2])), np.zeros((0, n, b))
    lane_steps = np.ascontiguousarray(lane_steps, dtype=float)
    lane_new = np.ascontiguousarray(lane_new, dtype=float)
    lanes = lane_steps.shape[0]
    if lane_steps.shape != (lanes, n, b, steps.shape[2]) or lane_new.shape != (lanes, n, b):
        raise ValueError(f"system_pcrb: lane_steps {lane_steps.shape} and lane_new {lane_new.shape} do not fit "
                         f"steps {steps.shape}")
    lane_fixed = fixed.copy()
    lane_fixed[:, system.bound_fixed.index("dt")] = 0.0
    lib = load(n_beacons, NO_MODELS)
    lib.sblsim_system_pcrb.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int,
                                       ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
    out = np.empty((n, b))
    if lib.sblsim_system_pcrb(n, b, fixed.ctypes.data, steps.ctypes.data, lanes, lane_fixed.ctypes.data,
                              lane_steps.ctypes.data, lane_new.ctypes.data, out.ctypes.data):
        raise MemoryError("system_pcrb: out of memory")
    return out


__all__ = ["metrics_sizes", "run_metrics", "system_bound_sizes", "system_pcrb"]
