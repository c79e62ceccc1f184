"""FMU script of the platform component (built by `sblsim fmus build`)."""

from models.platform import PlatformCore
from sblsim_slave import CoreSlave


class Platform(CoreSlave):
    """Platform component of sblsim as an FMI 2.0 Co-Simulation slave."""

    core_class = PlatformCore
