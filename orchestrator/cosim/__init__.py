"""The co-simulation kernel every command runs on: a configuration read and checked (:mod:`.config`), resolved
once into a plan (:mod:`.plan`), its components as handles on an engine (:mod:`.engines`: the local library or
FMUs), connected (:mod:`.connections`) and stepped by the master algorithm (:mod:`.master`), batches of runs with
their metrics, bound and output (:mod:`.run`, :mod:`.record_metrics`, :mod:`.metrics`, :mod:`.run_output`,
:mod:`.limits`) a user's receiver file (:mod:`.plugins`), and the system for other FMI hosts: FMUs built with a
scenario's values (:mod:`.scenario_fmus`), the SSP package (:mod:`.ssp`, read back by :mod:`.ssp_read`) and a run's
inputs for the generated receiver's C (:mod:`.codegen`)."""
