"""The names of a run's recorded columns and per-run metrics, shared by every layer that reads them.

The compiled metrics pass numbers its inputs and outputs from these tuples
(:mod:`sblsim.fmus.contract` generates the C enums), the orchestrator's
metrics, run, limits and campaigns name their columns with them. They live
here, below both, so that neither the FMU build nor the orchestrator has to
import the other for a list of names.
"""

from __future__ import annotations

from sblsim.models.acoustics.channel.interface import LANES
from sblsim.models.acoustics.channel.lanes import lane_name
from sblsim.models.receiver.interface import COVARIANCE, OPTIONAL_OUTPUTS

#: Per-run error metrics of an estimator (the receiver's; prefixed ``instr_`` for the instrumentation fix) [m].
METRIC_NAMES = ("e_x_mean", "e_y_mean", "e_z_mean", "e_tot_mean", "e_tot_rms", "e_tot_std")
#: Per-run consistency metrics, the bound and the divergence flag.
CONSISTENCY_NAMES = ("nees_mean", "coverage_95", "nis_mean", "gated_pct", "pcrb_rms", "diverged")
#: Every per-run metric: the receiver's errors, the instrumentation's, consistency and the bound (the compiled
#: pass numbers its outputs from this tuple: :mod:`sblsim.fmus.contract`).
RUN_METRICS = METRIC_NAMES + tuple(f"instr_{m}" for m in METRIC_NAMES) + CONSISTENCY_NAMES
#: Recorded outputs the metrics read (truth, estimate, instrumentation fix, NIS, gate, slot, packet, beacon,
#: covariance), in the order of the compiled pass (which numbers them from this tuple: :mod:`sblsim.fmus.contract`).
METRIC_INPUTS = tuple(f"{kind}_{a}" for kind in ("true", "est", "instr") for a in "xyz") + (
    "instr_valid", "nis", "gated", "packet_seq", "packet_valid", "beacon_id", "beacon_x", "beacon_y", "beacon_z",
    *(f"cov_{ab}" for ab in COVARIANCE))

#: Time-series columns: name -> recorded ``component.variable`` (besides time and the errors).
TIMESERIES_COLUMNS = {
    **{f"true_{a}": f"target.pos_{a}" for a in "xyz"},
    **{f"true_v{a}": f"target.vel_{a}" for a in "xyz"},
    **{f"est_{a}": f"receiver.est_{a}" for a in "xyz"},
    **{f"est_v{a}": f"receiver.est_v{a}" for a in "xyz"},
    "est_valid": "receiver.est_valid",
    **{f"instr_{a}": f"receiver.instr_{a}" for a in "xyz"},
    "instr_valid": "receiver.instr_valid",
    "packet_seq": "acoustics.packet_seq",
    "beacon_id": "acoustics.beacon_id",
    "packet_valid": "acoustics.packet_valid",
    "tx_time": "acoustics.tx_time",
    "rx_time": "acoustics.rx_time",
    "range": "acoustics.range",
    **{f"beacon_{a}": f"acoustics.beacon_{a}" for a in "xyz"},
    "depth": "target.depth_measured",
    "range_true": "acoustics.range_true",
    "travel_time": "acoustics.travel_time",
    "outlier": "acoustics.outlier",
    "launch_angle": "acoustics.launch_angle",
    "arrival_angle": "acoustics.arrival_angle",
    "arrival": "acoustics.arrival",
    "snr": "acoustics.snr",
    "detection_probability": "acoustics.detection_probability",
    "nis": "receiver.nis",
    "pos_std": "receiver.pos_std",
    **{f"cov_{ab}": f"receiver.cov_{ab}" for ab in COVARIANCE},
    "gated": "receiver.gated",
    "roll": "platform.roll",
    "pitch": "platform.pitch",
    "yaw": "platform.yaw",
}

#: Time-series columns a run's table has where its receiver has their output (a user's FMU may lack the receiver's
#: :data:`~sblsim.models.receiver.interface.OPTIONAL_OUTPUTS`; every built-in receiver has them).
OPTIONAL_COLUMNS = tuple(name for name, source in TIMESERIES_COLUMNS.items()
                         if source in {f"receiver.{output}" for output in OPTIONAL_OUTPUTS})

#: What the time series records of each lane 2 … :data:`~sblsim.models.acoustics.core.LANES` of a delivery (the
#: packets that arrived in a step after lane 1's, whose fields are the columns above): name -> recorded
#: ``component.variable``; a run's table has the columns of the lanes it used.
LANE_COLUMNS = {lane_name(m, name): f"acoustics.{lane_name(m, name)}" for m in range(2, LANES + 1)
                for name in ("packet_seq", "beacon_id", "packet_valid", "tx_time", "rx_time", "range", "beacon_x",
                             "beacon_y", "beacon_z", "range_true", "travel_time", "outlier")}

#: What the metrics read of a packet on a lane 2 … of a delivery (in this order, per lane).
LANE_FIELDS = ("packet_seq", "packet_valid", "beacon_id", "beacon_x", "beacon_y", "beacon_z")
#: The lanes' columns the metrics read besides :data:`METRIC_INPUTS`, lane by lane (:data:`LANE_FIELDS` each; the
#: compiled pass numbers them after those): recorded where a run's channel delivered two packets in one step,
#: zeros (no packet) where not.
LANE_METRIC_INPUTS = tuple(lane_name(m, name) for m in range(2, LANES + 1) for name in LANE_FIELDS)


def lane_source(lane: int, source: str) -> str:
    """The recorded ``component.variable`` of the channel's output ``source`` on ``lane`` (1-based)."""
    component, name = source.split(".", 1)
    return f"{component}.{lane_name(lane, name)}"


__all__ = ["CONSISTENCY_NAMES", "LANE_COLUMNS", "LANE_FIELDS", "LANE_METRIC_INPUTS", "lane_source", "METRIC_INPUTS",
           "METRIC_NAMES", "OPTIONAL_COLUMNS", "RUN_METRICS", "TIMESERIES_COLUMNS"]
