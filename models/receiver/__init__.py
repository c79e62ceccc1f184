"""Receiver component: the paper's EKF (casadi Jacobians) and the instrumentation fix."""

from models.receiver.core import ReceiverCore, receiver_interface
from models.receiver.ekf import ExtendedKalmanFilter
from models.receiver.jacobian import range_and_jacobian, range_function
from models.receiver.multilateration import multilaterate

__all__ = ["ReceiverCore", "receiver_interface", "ExtendedKalmanFilter", "range_and_jacobian",
           "range_function", "multilaterate"]
