"""Calibration surveys: the log format, readers of public formats, built-in surveys and ``sblsim calibrate``.

* :mod:`~sblsim.orchestrator.surveys.log`: sblsim's calibration survey log and its hostile-safe reader;
* :mod:`~sblsim.orchestrator.surveys.xie`: survey A's text format (Xie et al. 2023);
* :mod:`~sblsim.orchestrator.surveys.gnatss`: survey B's files (GNATSS's ``pxp_tt`` and
  ``POS_FREED_TRANS_TWTT``, site NCL1) joined into the log; the files read by
  :mod:`~sblsim.orchestrator.surveys.gnatss_files`, the site by :mod:`~sblsim.orchestrator.surveys.gnatss_site`,
  with its local east/north/up frame (:mod:`~sblsim.orchestrator.surveys.local_frame`) and harmonic-mean sound
  speeds (:mod:`~sblsim.orchestrator.surveys.harmonic_mean`);
* :mod:`~sblsim.orchestrator.surveys.calibrate`: ``sblsim calibrate``'s entry point, which re-exports what four
  modules hold: :mod:`~sblsim.orchestrator.surveys.settings` (the solver's settings),
  :mod:`~sblsim.orchestrator.surveys.survey` (a survey's definition, the built-in TOML files in this folder: the
  site and the solver's settings, and loading one), :mod:`~sblsim.orchestrator.surveys.solution` (its solution with
  :mod:`sblsim.models.calibration`) and :mod:`~sblsim.orchestrator.surveys.outputs` (its files).
"""
