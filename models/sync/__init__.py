"""Receiver clocks synchronised from sync tags (issue 68): the model and its robust sparse solve
(:mod:`~sblsim.models.sync.clocks`), each sync tag positioned from the synchronised arrivals
(:mod:`~sblsim.models.sync.positions`) and simulated sync-tag detections (:mod:`~sblsim.models.sync.simulate`).
No orchestrator import: the readers and the command are :mod:`sblsim.orchestrator.sync`."""
