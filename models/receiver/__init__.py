"""Receiver component: the paper's EKF (casadi Jacobians), the instrumentation fix and the
per-slot least-squares receiver."""

from models.receiver.core import Receiver, receiver_interface
from models.receiver.lsq import LeastSquaresReceiver
from models.receiver.measurement import position_range_function, range_function

__all__ = ["LeastSquaresReceiver", "Receiver", "position_range_function", "range_function", "receiver_interface"]
