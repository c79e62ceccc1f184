"""Acoustic channel component: round-robin OWTT ranging, sound speed, loss and multipath."""

from models.acoustics.core import AcousticsCore
from models.acoustics.sound_speed import SoundSpeedProfile, load_profile

__all__ = ["AcousticsCore", "SoundSpeedProfile", "load_profile"]
