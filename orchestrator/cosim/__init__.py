"""The co-simulation kernel every command runs on: a configuration read and checked (:mod:`.config`), resolved
once into a plan (:mod:`.plan`), its components as handles on an engine (:mod:`.engines`: the local library or
FMUs), connected (:mod:`.connections`) and stepped by the master algorithm (:mod:`.master`), batches of runs with
their metrics, bound and output (:mod:`.run`, :mod:`.metrics`, :mod:`.limits`) and a user's receiver file
(:mod:`.plugins`)."""
