"""Tracking a pinger heard by a fixed array (an inverted LBL), one job per module.

* :mod:`~sblsim.models.tracking.toa`: the TOA model and its Jacobian;
* :mod:`~sblsim.models.tracking.fix`: the single-ping fix;
* :mod:`~sblsim.models.tracking.calibration`: the sound speed fitted with the pings;
* :mod:`~sblsim.models.tracking.schedule`: the field's ping types (stable, random and pseudo-random burst
  intervals) as the time between successive pings, which the motion model's process noise follows; the type the
  rows show (:mod:`~sblsim.models.tracking.ping_type`), a pseudo-random sequence aligned to them
  (:mod:`~sblsim.models.tracking.burst_sequence`), the rows that cannot be pings set aside
  (:mod:`~sblsim.models.tracking.strays`);
* :mod:`~sblsim.models.tracking.ekf`, :mod:`~sblsim.models.tracking.filters`: the causal filters and the RTS
  smoother; :mod:`~sblsim.models.tracking.filter_consider`: the survey's and the speed's consider terms of their
  covariances;
* :mod:`~sblsim.models.tracking.smoother`, :mod:`~sblsim.models.tracking.starts`: the robust smoother and its
  starts; its problem and sums over the arrivals (:mod:`~sblsim.models.tracking.smoother_cost`), its normal
  equations and banded solves (:mod:`~sblsim.models.tracking.smoother_system`), its covariances
  (:mod:`~sblsim.models.tracking.smoother_covariance`); :mod:`~sblsim.models.tracking.motion_noise`: the motion
  model's noise estimated by EM;
* :mod:`~sblsim.models.tracking.quality`: every estimate checked against its own data, a lost stretch flagged;
* :mod:`~sblsim.models.tracking.geometry`: an array that cannot position a tag refused;
* :mod:`~sblsim.models.tracking.depth`: a tag's depth the receivers do not determine, taken with a prior;
* :mod:`~sblsim.models.tracking.receivers`: a receiver out of line of sight named from its residuals;
* :mod:`~sblsim.models.tracking.stationary`: a stationary tag's pings pooled into one position;
* :mod:`~sblsim.models.tracking.simulate`: simulated pings.

The public names are gathered in :mod:`sblsim.models.receiver.toa_tracking`; the accuracy limit is
:mod:`sblsim.models.receiver.toa_bound`.
"""
