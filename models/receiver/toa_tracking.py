"""Tracking a pinger from its times of arrival at a fixed, synchronised array (an inverted LBL): the public names of
the tracker, gathered from :mod:`sblsim.models.tracking`, where each part is a module of its own:

* :mod:`~sblsim.models.tracking.toa`: the TOA model ``toa_i = t_e + ‖p − r_i‖ / c + w_i`` and its Jacobian;
* :mod:`~sblsim.models.tracking.fix`: the single-ping fix (each ping alone, the emission time unknown);
* :mod:`~sblsim.models.tracking.calibration`: the sound speed fitted jointly with the pings (the replay's
  calibration);
* :mod:`~sblsim.models.tracking.schedule`: the ping types (stable, random, pseudo-random burst intervals) as the time
  between successive pings;
* :mod:`~sblsim.models.tracking.ekf`: the EKF (:class:`ToaTracker`) and the Rauch-Tung-Striebel smoother;
  :mod:`~sblsim.models.tracking.filters`: the sequential EKF and the UKF;
* :mod:`~sblsim.models.tracking.smoother` and :mod:`~sblsim.models.tracking.starts`: the robust smoother and where
  it starts; :mod:`~sblsim.models.tracking.motion_noise`: the motion model's noise estimated by EM;
* :mod:`~sblsim.models.tracking.stationary`: a stationary tag's pings pooled into one position;
* :mod:`~sblsim.models.tracking.quality`: each estimate checked against its own data;
  :mod:`~sblsim.models.tracking.receivers`: a receiver out of line of sight named;
* :mod:`~sblsim.models.tracking.simulate`: simulated pings of any ping type.

Units: seconds [s], metres [m], metres per second [m/s].

References
----------
Baktoft, Gjelland, Økland, Thygesen, "Positioning of aquatic animals based on time-of-arrival and random walk
models using YAPS (Yet Another Positioning Solver)", Scientific Reports 7:14294, 2017,
doi:10.1038/s41598-017-14278-z (the random-walk model of the track and of the emission times, and the Lake
Hald data).
"""

from __future__ import annotations

from sblsim.models.tracking.calibration import (
    BATCHES,
    JOINT_ITERATIONS,
    JOINT_TOLERANCE,
    MAX_SIGMA,
    ROBUST_SCALE,
    Calibration,
    calibrate_sound_speed,
    calibrate_sound_speed_robust,
)
from sblsim.models.tracking.ekf import ToaTracker, TrackerSettings, TrackRecord, rts_smooth
from sblsim.models.tracking.filters import (
    CAUSAL_TRACKERS,
    UKF_ALPHA,
    UKF_BETA,
    UKF_ITERATIONS,
    UKF_KAPPA,
    UKF_TOLERANCE,
    ToaSeqTracker,
    ToaUkfTracker,
)
from sblsim.models.tracking.fix import FIX_ITERATIONS, GATE_ONE, Fix, fix_pings, single_ping_fix
from sblsim.models.tracking.simulate import simulate_pings
from sblsim.models.tracking.smoother import (
    ROBUST_COARSE_ITERATIONS,
    ROBUST_COARSE_SCALE,
    ROBUST_ITERATIONS,
    ROBUST_KEPT_WEIGHT,
    ROBUST_SCREEN,
    ROBUST_TOLERANCE,
    RobustTrack,
    robust_smooth,
)
from sblsim.models.tracking.smoother_cost import ROBUST_DOF, observed_information
from sblsim.models.tracking.starts import anchored_start, graduated_start, robust_track
from sblsim.models.tracking.stationary import StationaryFix, stationary_fix
from sblsim.models.tracking.toa import SOUND_SPEED_RANGE, toa_function, toa_model

__all__ = ["BATCHES", "CAUSAL_TRACKERS", "FIX_ITERATIONS", "GATE_ONE", "JOINT_ITERATIONS", "JOINT_TOLERANCE",
           "MAX_SIGMA", "ROBUST_COARSE_ITERATIONS", "ROBUST_COARSE_SCALE", "ROBUST_DOF", "ROBUST_ITERATIONS",
           "ROBUST_KEPT_WEIGHT", "ROBUST_SCALE", "ROBUST_SCREEN", "ROBUST_TOLERANCE", "SOUND_SPEED_RANGE", "UKF_ALPHA",
           "UKF_BETA", "UKF_ITERATIONS", "UKF_KAPPA", "UKF_TOLERANCE", "Calibration", "Fix", "RobustTrack",
           "StationaryFix", "ToaSeqTracker", "ToaTracker",
           "ToaUkfTracker", "TrackRecord", "TrackerSettings", "anchored_start", "calibrate_sound_speed",
           "calibrate_sound_speed_robust", "fix_pings", "graduated_start", "observed_information", "robust_smooth",
           "robust_track", "rts_smooth", "simulate_pings", "single_ping_fix", "stationary_fix", "toa_function",
           "toa_model"]
