"""Target component: the diver's trajectories and depth sensor."""

from sblsim.models.target.core import Target, natural_duration, start_state

__all__ = ["Target", "natural_duration", "start_state"]
