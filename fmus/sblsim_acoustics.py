"""FMU script of the acoustics component (built by `sblsim fmus build`)."""

from models.acoustics import AcousticsCore
from sblsim_slave import CoreSlave


class Acoustics(CoreSlave):
    """Acoustics component of sblsim as an FMI 2.0 Co-Simulation slave."""

    core_class = AcousticsCore
