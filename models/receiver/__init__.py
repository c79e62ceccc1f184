"""Receivers: the paper's EKF, a sequential EKF, an unscented Kalman filter and the least-squares receiver.

Every receiver is one module: its declarations and its casadi predict and
update steps (:class:`sblsim.models.receiver.core.KalmanReceiver`), sharing the
motion model (:mod:`sblsim.models.receiver.motion`), the measurement models
(:mod:`sblsim.models.receiver.measurement`,
:mod:`sblsim.models.receiver.range_direction`), the Kalman arithmetic
(:mod:`sblsim.models.receiver.kalman`), the sigma points
(:mod:`sblsim.models.receiver.sigma_points`) and the NIS gate
(:mod:`sblsim.models.receiver.gate`). The accuracy bound is
:mod:`sblsim.models.bound`.
"""

from sblsim.models.receiver.core import KalmanReceiver
from sblsim.models.receiver.ekf import PaperEKF
from sblsim.models.receiver.ekf_seq import SequentialReceiver
from sblsim.models.receiver.interface import receiver_interface
from sblsim.models.receiver.lsq import LeastSquaresReceiver
from sblsim.models.receiver.measurement import (
    MeasurementModel,
    RangeDepthModel,
    position_range_function,
    range_function,
)
from sblsim.models.receiver.motion import CONSTANT_VELOCITY, ConstantVelocity
from sblsim.models.receiver.range_direction import RangeDirectionModel
from sblsim.models.receiver.ukf import UnscentedReceiver

__all__ = ["CONSTANT_VELOCITY", "ConstantVelocity", "KalmanReceiver", "LeastSquaresReceiver", "MeasurementModel",
           "PaperEKF", "RangeDepthModel", "RangeDirectionModel", "SequentialReceiver", "UnscentedReceiver",
           "position_range_function", "range_function", "receiver_interface"]
