"""Target component: the diver's trajectories and depth sensor."""

from models.target.core import TargetCore, natural_duration, start_state

__all__ = ["TargetCore", "natural_duration", "start_state"]
