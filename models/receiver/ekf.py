"""``ekf``: the paper's Extended Kalman Filter receiver.

At every slot it updates with the **latest range of every beacon heard so
far** plus the depth, ``z = [r_1 … r_n, d]`` with ``h_i(x) = ‖p − b̃_i‖``
(casadi Jacobian) and ``R = diag(σ_r², …, σ_r², σ_d²)`` (the joint update,
computed row after row: :func:`sblsim.models.receiver.kalman.ekf_update` with the
:class:`~sblsim.models.receiver.measurement.RangeDepthModel`): one range is
fresh, the others are held from earlier slots, and their staleness is part
of the error, as in the paper. A beacon not heard yet gets a zero Jacobian
row and a zero innovation (an exact no-op). An optional NIS gate (off by
default: the paper has none) refuses a fresh range whose own NIS exceeds the
χ²(1) quantile of ``gate_probability``; the held range of that beacon then
stays.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4.3.
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.declarations import Variable
from sblsim.models.receiver import kalman
from sblsim.models.receiver.core import KalmanReceiver
from sblsim.models.receiver.gate import gate, gate_parameters
from sblsim.models.receiver.interface import filter_parameters
from sblsim.models.receiver.measurement import RangeDepthModel
from sblsim.models.receiver.packets import fresh_range, take_packet
from sblsim.models.receiver.reacquisition import earlier_innovation, remember_rejected


def update(x: ca.SX, P: ca.SX, ranges: ca.SX, beacons: ca.SX, heard: ca.SX, depth, sigma_range, sigma_depth,
           model: RangeDepthModel | None = None, range_k=None) -> tuple[ca.SX, ca.SX, ca.SX]:
    """The paper's EKF update with the latest range of each beacon heard so far and the depth.

    Parameters
    ----------
    x : casadi.SX, (6, 1)
        Predicted state [m, m/s].
    P : casadi.SX, (6, 6)
        Predicted covariance.
    ranges : casadi.SX, (n, 1)
        Latest range of each beacon [m].
    beacons : casadi.SX, (3 n, 1)
        Broadcast position carried with each range [m], beacon after beacon.
    heard : casadi.SX, (n, 1)
        1 for a beacon heard so far, else 0 (its row is left out exactly).
    depth : casadi.SX
        Depth reading [m].
    sigma_range, sigma_depth : casadi.SX
        Standard deviations in R [m].
    model : RangeDepthModel, optional
        The measurement model (default a :class:`RangeDepthModel`).
    range_k : casadi.SX, optional
        The range law's growth [m/m]: each range's σ is ``sigma_range + range_k ‖p̂ − b_i‖`` at the predicted
        position (:meth:`RangeDepthModel.noise_variance`); None: ``sigma_range`` for every range.

    Returns
    -------
    x, P, nis : casadi.SX
        Updated state and covariance, and ``yᵀ S⁻¹ y`` [1].
    """
    model = model or RangeDepthModel()
    n = ranges.numel()
    context = [beacons[3 * i:3 * i + 3] for i in range(n)]
    law = {"sigma_range": sigma_range, "sigma_depth": sigma_depth}
    if range_k is not None:
        law["range_k"] = range_k
    return kalman.ekf_update(x, P, ca.vertcat(ranges, depth), model, context, model.variances(x, context, law),
                             available=[heard[i] for i in range(n)] + [None])


class PaperEKF(KalmanReceiver):
    """The paper's EKF receiver with the raw instrumentation fix."""

    name = "receiver"
    label = "ekf"

    @classmethod
    def parameters(cls, n_beacons: int) -> tuple[Variable, ...]:
        return filter_parameters() + gate_parameters(1.0)

    @classmethod
    def correct(cls, x: dict, u: dict, p: dict, n_beacons: int) -> dict:
        fresh, rng, beacon = fresh_range(x, u, n_beacons)

        def row(state, beacon):  # a range at the state: prediction, Jacobian row, variance
            return (*cls.measurement.range_row(state, beacon), cls.measurement.noise_variance(state, beacon, p))

        h, H, variance = row(x["x"], beacon)
        S = ca.mtimes([H, x["P"], H.T]) + variance
        checked = gate(rng - h, S, fresh, x, u, p, earlier_innovation(cls, x, u, x["x"], x["P"], row, n_beacons))
        held = take_packet(x, {**u, "packet_valid": checked["use"]}, n_beacons)
        state, P, nis = update(x["x"], x["P"], held["ranges"], held["beacons"], held["heard"], u["depth"],
                               p["sigma_range"], p["sigma_depth"], cls.measurement, p.get("range_k"))
        return {**held, "x": state, "P": P, "nis": nis, "gated": checked["gated"], "failed": checked["failed"],
                **remember_rejected(x, u, checked["rejecting"], rng, beacon, cls.epoch(u, p), n_beacons)}


__all__ = ["PaperEKF", "update"]
