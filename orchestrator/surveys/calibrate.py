"""``sblsim calibrate``: a survey's definition, its solution and its outputs.

A survey is a log (:mod:`sblsim.orchestrator.surveys.log`, or a public format it is read from), a *site* (the
local frame's origin and the transponders' ids and a-priori positions) and the solver's settings
(:data:`SOLVER_KEYS`). A built-in survey is a TOML file of this package (:data:`BUILTIN_SURVEYS`) whose log is
one of the package's data files (a text file of survey A, or a GNATSS folder with its own site, edited as
``survey.editing`` says); a log given on the command line comes with the default settings, the
transponders it names and a-priori positions guessed from it (:func:`guess_apriori`), and ``--set
solver.KEY=VALUE``. Each segment ``[start, end)`` of transmit times is solved alone
(:func:`sblsim.models.calibration.solve`), and the segments are combined as Xie et al. (2023) combine them
(:func:`sblsim.models.calibration.combine`); without segments the whole log is one.

Where each part is (this module is the command's entry point; the names are imported from here):

* :mod:`~sblsim.orchestrator.surveys.settings`: the solver's settings, declared, checked, overridden, defaulted;
* :mod:`~sblsim.orchestrator.surveys.survey`: a survey (:class:`Survey`), the built-in surveys and loading one
  (:func:`load_survey`);
* :mod:`~sblsim.orchestrator.surveys.solution`: a survey solved and its segments combined (:func:`calibrate`,
  :class:`Calibration`);
* :mod:`~sblsim.orchestrator.surveys.outputs`: the files written (:func:`write_calibration`).
"""

from __future__ import annotations

from sblsim.orchestrator.surveys.outputs import (
    OUTPUT_FILES,
    PERTURBATION_FILES,
    RUNNING_FILES,
    SEARCH_FILES,
    write_calibration,
)
from sblsim.orchestrator.surveys.settings import (
    PROPAGATIONS,
    SEARCH_KEYS,
    SOLVER_KEYS,
    SOLVER_VARIABLES,
    apply_solver_overrides,
    check_solver,
    solver_defaults,
    solver_value,
)
from sblsim.orchestrator.surveys.solution import (
    NTD_COLUMNS,
    RUNNING_COLUMNS,
    Calibration,
    calibrate,
    leg_model,
    perturbations,
    profile_of,
)
from sblsim.orchestrator.surveys.survey import BUILTIN_SURVEYS, EDITINGS, FORMATS, Survey, guess_apriori, load_survey

__all__ = ["BUILTIN_SURVEYS", "Calibration", "EDITINGS", "FORMATS", "NTD_COLUMNS", "OUTPUT_FILES", "PERTURBATION_FILES",
           "PROPAGATIONS", "RUNNING_COLUMNS", "RUNNING_FILES", "SEARCH_FILES", "SEARCH_KEYS", "SOLVER_KEYS",
           "SOLVER_VARIABLES", "Survey", "apply_solver_overrides", "calibrate", "check_solver", "guess_apriori",
           "leg_model", "load_survey", "perturbations", "profile_of", "solver_defaults", "solver_value",
           "write_calibration"]
