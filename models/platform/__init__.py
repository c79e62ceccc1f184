"""Platform component: SBL base with beacons, wave motion, GPS and IMU."""

from models.platform.core import PlatformCore, beacon_names
from models.platform.geometry import beacon_positions, cross_offsets, rotation_ned

__all__ = ["PlatformCore", "beacon_names", "beacon_positions", "cross_offsets", "rotation_ned"]
