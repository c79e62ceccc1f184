"""FMU script of the least-squares receiver (built by `sblsim fmus build`)."""

from models.receiver.lsq import LeastSquaresReceiverCore
from sblsim_slave import CoreSlave


class ReceiverLsq(CoreSlave):
    """Per-step least-squares multilateration receiver of sblsim as an FMI 2.0 Co-Simulation slave."""

    core_class = LeastSquaresReceiverCore
