"""Acoustic channel component: round-robin OWTT ranging, sound speed, loss and multipath."""

from sblsim.models.acoustics.channel.component import Acoustics
from sblsim.models.acoustics.channel.interface import PACKET
from sblsim.models.acoustics.sound_speed import profile_table

__all__ = ["PACKET", "Acoustics", "profile_table"]
