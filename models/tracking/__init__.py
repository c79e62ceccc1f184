"""Tracking a pinger heard by a fixed array (an inverted LBL): what the tracker needs beyond the TOA model.

* :mod:`sblsim.models.tracking.schedule`: the ping types of the field (stable, random and pseudo-random burst
  intervals) as the time between successive pings, which the motion model's process noise follows;
* :mod:`sblsim.models.tracking.quality`: every estimate checked against its own data (the single-ping fixes, the
  physical speed), a lost stretch flagged per ping.

The TOA model, the fix, the filters and the smoothers are :mod:`sblsim.models.receiver.toa_tracking`; the accuracy
limit is :mod:`sblsim.models.receiver.toa_bound`.
"""
