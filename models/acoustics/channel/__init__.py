"""The acoustic channel, one job per module: round-robin OWTT or TWTT ranging with loss and multipath, USBL range and
direction of arrival, and the inverted LBL's times of arrival of a target's pings.

Where each part is (each module imports only the modules listed before it; import the names from the module that
defines them, this package's face imports nothing):

* :mod:`~sblsim.models.acoustics.channel.interface`: the channel's declared variables (the packet, the truth of
  its exchange, USBL's direction, the propagation, the detection, the range law) and the constants the modules
  share (ranging modes, in-flight places, lanes, random streams);
* :mod:`~sblsim.models.acoustics.channel.ocean`: the moving ocean, the travel times' slow change in time;
* :mod:`~sblsim.models.acoustics.channel.site`: the site's numbers of the sonar equation (noise, absorption, the
  sea floor);
* :mod:`~sblsim.models.acoustics.channel.lanes`: the packets in flight and the delivery lanes they arrive on, and
  the refusal of a run whose packets stay in flight too long (:func:`~.lanes.check_in_flight`);
* :mod:`~sblsim.models.acoustics.channel.pinger`: the pinger's schedule, **when the tag pings**: the stable,
  **random** (``rbi``) and pseudo-random burst intervals, the nominal epochs the receivers know, and the checks;
* :mod:`~sblsim.models.acoustics.channel.legs`: a leg's travel time (fixed-point one way to the moving diver,
  straight or along the eigenray) and what is heard of it;
* :mod:`~sblsim.models.acoustics.channel.exchange`: **how a slot's exchange is timed**, one way, two way (the
  interrogation, the turnaround and the reply) or USBL's with its direction of arrival, and what it measures;
* :mod:`~sblsim.models.acoustics.channel.toa`: the times of arrival of a ping at the fixed receivers of an
  inverted LBL;
* :mod:`~sblsim.models.acoustics.channel.component`: the component :class:`~.component.Acoustics`, its variables
  in their order, its parameters and its program (events, delivery, streams);
* :mod:`~sblsim.models.acoustics.channel.site_levels`: the site's eigenrays and levels between pairs of points in
  numbers (maps, design).

:mod:`sblsim.models.acoustics.core` keeps the channel's public names where they were before the package (a
re-export only).
"""
