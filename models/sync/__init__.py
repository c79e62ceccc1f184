"""Receiver clocks synchronised from sync tags (issue 68): the model and its robust sparse solve
(:mod:`~sblsim.models.sync.clocks`; the arrivals grouped into emissions, :mod:`~sblsim.models.sync.emissions`; the
fitted clocks, :mod:`~sblsim.models.sync.clock_fit`; the sigmas' selected inverse,
:mod:`~sblsim.models.sync.selected_inversion`), a clock's breaks (:mod:`~sblsim.models.sync.breaks`, searched by
:mod:`~sblsim.models.sync.change_points`; its clock parts aligned, :mod:`~sblsim.models.sync.clock_parts`), each sync
tag positioned from the synchronised arrivals
(:mod:`~sblsim.models.sync.positions`) and simulated sync-tag detections (:mod:`~sblsim.models.sync.simulate`).
No orchestrator import: the readers and the command are :mod:`sblsim.orchestrator.sync`."""
