"""The study's front door: every file a telemetry user brings, read as hostile input, one module per format.

The pipeline runs one way: these readers → the clocks (:mod:`sblsim.orchestrator.sync`) → the tracks
(:mod:`sblsim.orchestrator.tracks`) → the study (:mod:`sblsim.orchestrator.telemetry`); nothing here imports from
those rooms. Each reader returns one of a few tables (detections with UTC times and full transmitter IDs:
:mod:`.detections`; deployments with positions and time windows: :mod:`.deployments`; a tag sheet: :mod:`.tag_sheet`),
bounded by :mod:`.limits` and checked cell by cell (:mod:`.cells`).
"""
