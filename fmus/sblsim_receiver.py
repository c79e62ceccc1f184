"""FMU script of the receiver component (built by `sblsim fmus build`)."""

from models.receiver import ReceiverCore
from sblsim_slave import CoreSlave


class Receiver(CoreSlave):
    """Receiver component of sblsim as an FMI 2.0 Co-Simulation slave."""

    core_class = ReceiverCore
