"""Pure model cores of sblsim's four FMI components (no FMI or orchestrator imports).

``COMPONENTS`` maps each component name to its core class.
"""

from models.acoustics import AcousticsCore
from models.platform import PlatformCore
from models.receiver import LeastSquaresReceiverCore, ReceiverCore
from models.target import TargetCore

COMPONENTS = {c.name: c for c in (PlatformCore, AcousticsCore, TargetCore, ReceiverCore)}
#: Every core by its own name: the four components and the alternative receivers.
CORES = {**COMPONENTS, LeastSquaresReceiverCore.name: LeastSquaresReceiverCore}

__all__ = ["COMPONENTS", "CORES", "AcousticsCore", "PlatformCore", "ReceiverCore", "TargetCore"]
