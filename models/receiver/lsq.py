"""Least-squares receiver core: a per-slot Gauss-Newton multilateration fix, no filter.

At every new slot (see :class:`~models.receiver.core.PacketReceiverCore`) the
receiver fits its position to the held range of every beacon heard so far and
the depth reading by weighted least squares,

``F(p) = Σ_i ((r_i − ‖p − b_i‖) / σ_r)² + ((d − p_z) / σ_d)²``,

with :func:`~models.receiver.multilateration.multilaterate` (Taylor-series,
i.e. damped Gauss-Newton, iterations) started from the previous fix. Nothing
is filtered: the estimate is the latest valid fix, and the velocity is the
finite difference of the last two valid fixes over the time between their
slots. The receiver is its own instrumentation: ``instr_*`` is the same fix.

At the solution ``p̂`` it also reports the fit's weighted sum of squared
residuals ``F(p̂)`` (``nis``; chi-square with ``n + 1 − 3`` degrees of
freedom for correct σ and n ranges) and the Gauss-Newton position covariance
``(JᵀWJ)⁻¹`` through ``pos_std = sqrt(trace((JᵀWJ)⁻¹))``, where ``J`` stacks
the range gradients ``∂‖p − b_i‖/∂p`` (casadi-derived,
:func:`~models.receiver.jacobian.position_range_numpy`) and the depth row
``(0, 0, 1)``, and ``W = diag(1/σ_r², …, 1/σ_r², 1/σ_d²)``.

References
----------
Foy, "Position-location solutions by Taylor-series estimation", IEEE Trans.
Aerospace and Electronic Systems AES-12(2), 187-194, 1976.
Kay, Fundamentals of Statistical Signal Processing, Vol. 1: Estimation
Theory, Prentice Hall 1993: Chapter 8 (nonlinear least squares, the
Gauss-Newton iteration) and Chapter 3 (the Fisher information ``JᵀWJ`` of
Gaussian measurements, whose inverse bounds the covariance of the estimate).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from models.core import SEED_PARAMETERS, Variable
from models.receiver.core import PacketReceiverCore, ReceiverCore, receiver_interface
from models.receiver.jacobian import position_range_numpy
from models.receiver.multilateration import multilaterate

#: Parameters taken from :class:`ReceiverCore`'s declarations (declared once, there).
SHARED_PARAMETERS = ("sigma_range", "sigma_depth", "x0_x", "x0_y", "x0_z")
#: Smallest standard deviation used in the weights [m]; the floor of :func:`multilaterate`.
SIGMA_FLOOR = 1e-3


class LeastSquaresReceiverCore(PacketReceiverCore):
    """Per-slot weighted least-squares (Gauss-Newton) multilateration receiver.

    Parameters are ``sigma_range`` and ``sigma_depth`` (the weights
    ``1/σ²`` [m]), the initial guess ``x0_x, x0_y, x0_z`` [m] and the seed
    keys (taken for a uniform interface; the receiver draws no random numbers).

    Attributes
    ----------
    fix : ndarray, shape (B, 3)
        Latest valid fix [m]; the initial guess x0 until the first one.
    has_fix : ndarray of bool, shape (B,)
        A valid fix has been made.
    fix_time : ndarray, shape (B,)
        Slot epoch (``tx_time``) of :attr:`fix` [s] (NaN: none yet).
    velocity : ndarray, shape (B, 3)
        ``(fix − previous fix) / (time between their slots)`` [m/s]; 0 until
        two valid fixes exist.
    instr : ndarray, shape (B, 3)
        Fix of the latest slot [m] (NaN: that slot gave no valid fix).
    instr_valid : ndarray of bool, shape (B,)
        The latest slot gave a valid fix.
    nis : ndarray, shape (B,)
        Weighted sum of squared residuals ``F`` at the latest slot's fix [1]
        (NaN: no valid fix).
    pos_std : ndarray, shape (B,)
        ``sqrt(trace((JᵀWJ)⁻¹))`` at the latest slot's fix [m] (NaN: no valid fix).
    """

    name = "receiver_lsq"
    component_index = 3
    batched_parameters = frozenset({"cell", "sigma_range", "sigma_depth", "x0_x", "x0_y", "x0_z"})
    #: Iteration cap and step tolerance [standard deviations of the fix] of
    #: :func:`multilaterate`: tighter than the instrumentation's defaults,
    #: since the fix is this receiver's estimate.
    iterations: ClassVar[int] = 50
    tolerance: ClassVar[float] = 1e-6

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        ekf = {v.name: v for v in ReceiverCore.variables(n_beacons) if v.causality == "parameter"}
        return tuple(ekf[n] for n in SHARED_PARAMETERS) + SEED_PARAMETERS + receiver_interface()

    def _initial_state(self, t0: float) -> None:
        p = self.params
        nan = np.full(self.batch, np.nan)
        self.fix = np.column_stack([np.broadcast_to(np.asarray(p[f"x0_{a}"], float), self.batch)
                                    for a in ("x", "y", "z")])
        self.has_fix = np.zeros(self.batch, dtype=bool)
        self.fix_time = nan.copy()
        self.velocity = np.zeros((self.batch, 3))
        self.instr = np.full((self.batch, 3), np.nan)
        self.instr_valid = np.zeros(self.batch, dtype=bool)
        self.nis = nan.copy()
        self.pos_std = nan.copy()

    def _update(self, slot: np.ndarray, depth: np.ndarray) -> None:
        """Fix, fit statistics and finite-difference velocity for the replicates with a new slot."""
        p = self.params
        fix, valid = multilaterate(self.ranges, self.beacons, depth, self.fix, p["sigma_range"],
                                   p["sigma_depth"], iterations=self.iterations, tolerance=self.tolerance)
        new = slot & valid
        rows = np.flatnonzero(new)
        nis, pos_std = np.full(self.batch, np.nan), np.full(self.batch, np.nan)
        nis[rows], pos_std[rows] = fit_statistics(fix[rows], self.ranges[rows], self.beacons[rows], depth[rows],
                                                  _per_row(p["sigma_range"], self.batch)[rows],
                                                  _per_row(p["sigma_depth"], self.batch)[rows])
        self.nis = np.where(slot, nis, self.nis)
        self.pos_std = np.where(slot, pos_std, self.pos_std)
        self.instr = np.where(slot[:, None], fix, self.instr)
        self.instr_valid = np.where(slot, valid, self.instr_valid)

        elapsed = self.slot_time - self.fix_time  # NaN before the first fix
        with np.errstate(invalid="ignore", divide="ignore"):
            rate = (fix - self.fix) / elapsed[:, None]
        differentiate = new & self.has_fix & (elapsed > 0.0)
        self.velocity = np.where(differentiate[:, None], rate, self.velocity)
        self.fix = np.where(new[:, None], fix, self.fix)
        self.fix_time = np.where(new, self.slot_time, self.fix_time)
        self.has_fix = self.has_fix | new

    def _outputs(self) -> None:
        self.outputs = {f"est_{a}": self.fix[:, k].copy() for k, a in enumerate(("x", "y", "z"))}
        self.outputs.update({f"est_v{a}": self.velocity[:, k].copy() for k, a in enumerate(("x", "y", "z"))})
        self.outputs.update({f"instr_{a}": self.instr[:, k].copy() for k, a in enumerate(("x", "y", "z"))})
        self.outputs["instr_valid"] = self.instr_valid.copy()
        self.outputs["nis"] = self.nis.copy()
        self.outputs["pos_std"] = self.pos_std.copy()


def fit_statistics(position: np.ndarray, ranges: np.ndarray, beacons: np.ndarray, depth: np.ndarray,
                   sigma_range: np.ndarray, sigma_depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted residual sum of squares and Gauss-Newton position spread at a fix.

    ``F = Σ_i w_r (r_i − ‖p − b_i‖)² + w_d (d − p_z)²`` over the available
    ranges, and ``sqrt(trace(A⁻¹))`` with ``A = JᵀWJ = Σ_i w_r ∇h_i ∇h_iᵀ +
    w_d e_z e_zᵀ`` (``∇h_i`` from casadi, the inverse's trace by cofactors),
    with ``w = 1/max(σ, 1 mm)²`` as in :func:`multilaterate`. Every
    operation is element-wise over replicates, so a replicate's numbers do
    not depend on the batch.

    Parameters
    ----------
    position : ndarray, shape (B, 3)
        Fix p [m].
    ranges : ndarray, shape (B, n)
        Ranges [m]; NaN where missing (left out).
    beacons : ndarray, shape (B, n, 3)
        Beacon positions [m].
    depth : ndarray, shape (B,)
        Depth reading [m].
    sigma_range, sigma_depth : ndarray, shape (B,)
        Standard deviations [m].

    Returns
    -------
    rss : ndarray, shape (B,)
        ``F`` at the fix [1].
    spread : ndarray, shape (B,)
        ``sqrt(trace((JᵀWJ)⁻¹))`` [m]; NaN where ``JᵀWJ`` is singular.

    References
    ----------
    Kay (1993), see the module.
    """
    have = np.isfinite(ranges)
    w_r = np.where(have, 1.0 / np.maximum(sigma_range, SIGMA_FLOOR)[:, None] ** 2, 0.0)  # (B, n)
    w_d = 1.0 / np.maximum(sigma_depth, SIGMA_FLOOR) ** 2
    b = np.moveaxis(np.where(np.isfinite(beacons), beacons, 0.0), -1, 0)  # (3, B, n)
    (h,), J = position_range_numpy()(np.moveaxis(position, -1, 0)[:, :, None], b)  # (B, n), (3, B, n)
    J = np.where(have, J, 0.0)  # a missing beacon (placed at 0) may give 0/0 = NaN; its weight is 0
    res = np.where(have, ranges - h, 0.0)
    dres = depth - position[:, 2]
    rss = np.sum(w_r * res * res, axis=-1) + w_d * dres * dres
    a = {(i, j): np.sum(w_r * J[i] * J[j], axis=-1) for i in range(3) for j in range(i, 3)}
    a[2, 2] = a[2, 2] + w_d
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[1, 2]
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[0, 2]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[0, 1]
    det = a[0, 0] * c00 + a[0, 1] * (a[0, 2] * a[1, 2] - a[0, 1] * a[2, 2]) + a[0, 2] * (
        a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        spread = np.sqrt((c00 + c11 + c22) / det)
    return rss, np.where(det > 0.0, spread, np.nan)


def _per_row(value, batch: int) -> np.ndarray:
    """A scalar or per-replicate parameter as an array of shape (B,)."""
    return np.broadcast_to(np.asarray(value, dtype=float), (batch,))
