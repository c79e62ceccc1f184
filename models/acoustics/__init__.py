"""Acoustic channel component: round-robin OWTT ranging, sound speed, loss and multipath."""

from models.acoustics.core import PACKET, Acoustics
from models.acoustics.sound_speed import profile_table

__all__ = ["PACKET", "Acoustics", "profile_table"]
