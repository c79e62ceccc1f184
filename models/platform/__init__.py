"""Platform component: SBL base with beacons, wave motion, GPS and IMU."""

from sblsim.models.platform.core import Platform, beacon_names, beacon_variables
from sblsim.models.platform.geometry import beacon_positions, cross_offsets, parse_offsets, rotation_ned

__all__ = ["Platform", "beacon_names", "beacon_positions", "beacon_variables", "cross_offsets", "parse_offsets",
           "rotation_ned"]
