"""The timing noise of a time of arrival: the value a tracker assumes where nothing else is known, and the ranges a
user's timing noise and a receiver's clock uncertainty may take (the measurement model: :mod:`.toa`). Light: the
command line reads these without loading the model's casadi functions."""

from __future__ import annotations

#: The standard deviation of a time of arrival the tracker assumes [s] (Lake Hald's single-ping residuals: 0.13 ms
#: by their median absolute deviation, 0.15 ms by their standard deviation), where nothing else is known: neither
#: given (``--toa-sigma``) nor a synchronisation's per receiver (a receivers file's ``toa_sigma_s``).
SIGMA_TOA = 1.5e-4

#: The timing noise a user may give, and a receivers file's ``toa_sigma_s`` may hold [s]: a microsecond to a second.
TOA_SIGMA_RANGE = (1e-6, 1.0)
#: A receiver's clock offset's own uncertainty a synchronisation's ``offsets.csv`` and a receivers file's
#: ``clock_sigma_s`` may hold [s] (0 at the reference receiver): a stationary tag's consider term.
CLOCK_SIGMA_RANGE = (0.0, 1.0)


__all__ = ["CLOCK_SIGMA_RANGE", "SIGMA_TOA", "TOA_SIGMA_RANGE"]
