"""Receiver component: the paper's EKF (casadi Jacobians), the instrumentation fix and the
per-slot least-squares receiver."""

from models.receiver.core import PacketReceiverCore, ReceiverCore, receiver_interface
from models.receiver.ekf import ExtendedKalmanFilter
from models.receiver.jacobian import range_and_jacobian, range_function
from models.receiver.lsq import LeastSquaresReceiverCore
from models.receiver.multilateration import multilaterate

__all__ = ["ExtendedKalmanFilter", "LeastSquaresReceiverCore", "PacketReceiverCore", "ReceiverCore", "multilaterate",
           "range_and_jacobian", "range_function", "receiver_interface"]
