"""Receivers: the paper's EKF, a sequential EKF, an unscented Kalman filter and the least-squares receiver.

Every receiver is one module: its declarations and its casadi predict and
update steps (:class:`sblsim.models.receiver.core.KalmanReceiver`), sharing the
measurement model (:mod:`sblsim.models.receiver.measurement`).
"""

from sblsim.models.receiver.core import KalmanReceiver, receiver_interface
from sblsim.models.receiver.ekf import PaperEKF
from sblsim.models.receiver.ekf_seq import SequentialReceiver
from sblsim.models.receiver.lsq import LeastSquaresReceiver
from sblsim.models.receiver.measurement import RangeDepthModel, position_range_function, range_function
from sblsim.models.receiver.ukf import UnscentedReceiver

__all__ = ["KalmanReceiver", "LeastSquaresReceiver", "PaperEKF", "RangeDepthModel", "SequentialReceiver",
           "UnscentedReceiver", "position_range_function", "range_function", "receiver_interface"]
