"""Receivers: the paper's EKF, a sequential EKF, an unscented Kalman filter and the least-squares receiver.

Every receiver is one module: its declarations and its casadi predict and
update steps (:class:`models.receiver.core.KalmanReceiver`), sharing the
measurement model (:mod:`models.receiver.measurement`).
"""

from models.receiver.core import KalmanReceiver, receiver_interface
from models.receiver.ekf import Receiver
from models.receiver.ekf_seq import SequentialReceiver
from models.receiver.lsq import LeastSquaresReceiver
from models.receiver.measurement import RangeDepthModel, position_range_function, range_function
from models.receiver.ukf import UnscentedReceiver

__all__ = ["KalmanReceiver", "LeastSquaresReceiver", "RangeDepthModel", "Receiver", "SequentialReceiver",
           "UnscentedReceiver", "position_range_function", "range_function", "receiver_interface"]
