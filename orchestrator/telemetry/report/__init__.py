"""A telemetry study's report (``report.html``): one self-contained page a user opens offline, written by every
``sblsim track`` and by ``sblsim report DIR`` for a study already run.

- :mod:`.daily`: the kept detections per receiver and day (``detections_daily.csv``);
- :mod:`.folder`: a study's folder read back, as hostile input;
- :mod:`.images`: a figure as an inline PNG;
- :mod:`.figures_study`, :mod:`.figures_tag`: the study's, the clocks' and each tag's figures, with their numbers;
- :mod:`.decisions`: the warnings and the values taken that the user could have given;
- :mod:`.context`: what the page shows; :mod:`.page`: the page rendered (Jinja2, ``templates/report.html.j2``).
"""
