"""Pure model code of sblsim's FMI components (no FMI or orchestrator imports).

``COMPONENTS`` maps each component of the system to its model class (the
paper's EKF for ``receiver``); ``MODELS`` maps every model by its own name,
the alternative receivers included.
"""

from sblsim.models.acoustics import Acoustics
from sblsim.models.platform import Platform
from sblsim.models.receiver import LeastSquaresReceiver, PaperEKF, SequentialReceiver, UnscentedReceiver
from sblsim.models.systems import SYSTEMS, lbl, sbl, usbl  # noqa: F401 (each system module registers itself)
from sblsim.models.target import Target

COMPONENTS = {c.name: c for c in (Platform, Acoustics, Target, PaperEKF)}
#: Built-in receivers: ``simulation.receiver`` value -> model.
RECEIVER_MODELS = {"ekf": PaperEKF, "ekf-seq": SequentialReceiver, "ukf": UnscentedReceiver,
                   "lsq": LeastSquaresReceiver}
#: Built-in receivers: ``simulation.receiver`` value -> model name.
RECEIVERS = {key: model.name for key, model in RECEIVER_MODELS.items()}
#: Every model by its own name: the four components and the alternative receivers.
MODELS = {**COMPONENTS, **{model.name: model for model in RECEIVER_MODELS.values()}}

__all__ = ["COMPONENTS", "MODELS", "RECEIVERS", "RECEIVER_MODELS", "Acoustics", "LeastSquaresReceiver", "Platform",
           "Receiver", "SequentialReceiver", "Target", "UnscentedReceiver"]
