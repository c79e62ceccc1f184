"""Pure model code of sblsim's FMI components (no FMI or orchestrator imports).

``COMPONENTS`` maps each component of the system to its model class (the
paper's EKF for ``receiver``); ``MODELS`` maps every model by its own name,
the alternative receivers included.
"""

from models.acoustics import Acoustics
from models.platform import Platform
from models.receiver import LeastSquaresReceiver, Receiver
from models.target import Target

COMPONENTS = {c.name: c for c in (Platform, Acoustics, Target, Receiver)}
#: Every model by its own name: the four components and the alternative receivers.
MODELS = {**COMPONENTS, LeastSquaresReceiver.name: LeastSquaresReceiver}
#: Built-in receivers: ``simulation.receiver`` value -> model name.
RECEIVERS = {"ekf": Receiver.name, "lsq": LeastSquaresReceiver.name}

__all__ = ["COMPONENTS", "MODELS", "RECEIVERS", "Acoustics", "LeastSquaresReceiver", "Platform", "Receiver", "Target"]
