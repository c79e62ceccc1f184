"""Pure model code of sblsim's FMI components (no FMI or orchestrator imports).

``COMPONENTS`` maps each component of the system to its model class (the
paper's EKF for ``receiver``); ``MODELS`` maps every model by its own name,
the alternative receivers included. The error kinds of :mod:`sblsim.models.errors`
are re-exported here (``from sblsim.models import SblsimError``).
"""

import importlib
import pkgutil

from sblsim.models import systems as _systems
from sblsim.models.acoustics import Acoustics
from sblsim.models.errors import (
    ArchiveError,
    CampaignError,
    CompileError,
    ConfigError,
    FMICallError,
    ModelError,
    SblsimError,
)
from sblsim.models.platform import Platform
from sblsim.models.receiver import LeastSquaresReceiver, PaperEKF, SequentialReceiver, UnscentedReceiver
from sblsim.models.target import Target

# Every module of sblsim.models.systems registers its system on import (docs/systems.md): a new system is a new
# module there, found here, listed by sblsim.models.systems.SYSTEMS in the order of the systems' codes.
for _module in pkgutil.iter_modules(_systems.__path__):
    importlib.import_module(f"{_systems.__name__}.{_module.name}")

COMPONENTS = {c.name: c for c in (Platform, Acoustics, Target, PaperEKF)}
#: Built-in receivers: ``simulation.receiver`` value -> model.
RECEIVER_MODELS = {"ekf": PaperEKF, "ekf-seq": SequentialReceiver, "ukf": UnscentedReceiver,
                   "lsq": LeastSquaresReceiver}
#: Built-in receivers: ``simulation.receiver`` value -> model name.
RECEIVERS = {key: model.name for key, model in RECEIVER_MODELS.items()}
#: Every model by its own name: the four components and the alternative receivers.
MODELS = {**COMPONENTS, **{model.name: model for model in RECEIVER_MODELS.values()}}

__all__ = ["COMPONENTS", "MODELS", "RECEIVERS", "RECEIVER_MODELS", "Acoustics", "ArchiveError", "CampaignError",
           "CompileError", "ConfigError", "FMICallError", "LeastSquaresReceiver", "ModelError", "PaperEKF", "Platform",
           "SblsimError", "SequentialReceiver", "Target", "UnscentedReceiver"]
