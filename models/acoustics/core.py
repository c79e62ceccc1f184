"""The acoustic channel's public names where they were before the channel became a package: a re-export only.

The channel's code is :mod:`sblsim.models.acoustics.channel`, one job per module (its docstring lists them): the
declared interface, the moving ocean, the site, the delivery lanes, the pinger's schedule, a leg, a slot's exchange,
the times of arrival, the component and the site's levels. New code imports each name from the module that defines
it; this module keeps the names a user's code or a generated header (the FMUs' contract header names
``sblsim.models.acoustics.core.LANES`` and ``ARRIVAL_SLACK``) may still refer to here.
"""

from __future__ import annotations

from sblsim.models.acoustics.channel.component import Acoustics
from sblsim.models.acoustics.channel.interface import (
    ARRIVAL,
    ARRIVAL_SLACK,
    ATTITUDE_ANGLES,
    DETECTION,
    DIRECTION,
    DOA_ARRAY,
    EXCHANGE,
    FAMILY_TABLE_VARIABLES,
    FIXED_KEYS,
    FLIGHT_CAPACITY,
    LANES,
    OVERFLOW,
    OVERRUN,
    OWTT_ITERATIONS,
    PACKET,
    PROPAGATION,
    RANGING,
    SNR_KEYS,
    TARGET_INPUTS,
    TOA,
)
from sblsim.models.acoustics.channel.lanes import check_in_flight, lane_fields, lane_name, lane_of, lane_variables
from sblsim.models.acoustics.channel.ocean import OCEAN_FEATURES, OCEAN_VARIABLES, ocean_perturbation
from sblsim.models.acoustics.channel.pinger import (
    BURSTS,
    MAX_BURSTS,
    MAX_PING_INTERVAL,
    PBI,
    PING_KEYS,
    PING_TYPES,
    PING_VARIABLES,
    RBI,
    RECEIVER_CLOCK_VARIABLES,
    burst_sequence,
    check_pinger,
    nominal_ping_interval,
    ping_due,
    ping_interval_drawn,
    ping_intervals,
    ping_nominal,
    ping_spread,
    sent_epoch,
)
from sblsim.models.acoustics.channel.site import site_numbers
from sblsim.models.acoustics.channel.site_levels import site_levels, site_vector

__all__ = ["Acoustics", "ARRIVAL", "ARRIVAL_SLACK", "ATTITUDE_ANGLES", "BURSTS", "burst_sequence", "check_in_flight",
           "check_pinger", "MAX_BURSTS", "MAX_PING_INTERVAL", "PBI", "PING_KEYS", "PING_TYPES", "ping_interval_drawn",
           "ping_intervals", "ping_nominal", "ping_spread", "RBI", "DETECTION", "DIRECTION",
           "DOA_ARRAY", "EXCHANGE", "FAMILY_TABLE_VARIABLES", "FIXED_KEYS", "FLIGHT_CAPACITY", "LANES", "lane_fields",
           "lane_name", "lane_of", "lane_variables", "nominal_ping_interval", "OCEAN_FEATURES", "ocean_perturbation",
           "OCEAN_VARIABLES",
           "OVERFLOW", "OVERRUN", "OWTT_ITERATIONS", "PACKET", "PING_VARIABLES", "ping_due", "PROPAGATION", "RANGING",
           "RECEIVER_CLOCK_VARIABLES",
           "sent_epoch", "site_levels", "site_numbers", "site_vector", "SNR_KEYS", "TARGET_INPUTS", "TOA"]
