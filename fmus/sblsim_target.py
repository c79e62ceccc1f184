"""FMU script of the target component (built by `sblsim fmus build`)."""

from models.target import TargetCore
from sblsim_slave import CoreSlave


class Target(CoreSlave):
    """Target component of sblsim as an FMI 2.0 Co-Simulation slave."""

    core_class = TargetCore
