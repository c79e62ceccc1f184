"""Recorded tracks of a moving target: times of arrival at a fixed array of receivers (an inverted LBL) read as
hostile input (:mod:`.toa`), tracked by :mod:`sblsim.models.tracking` and scored against a truth
track (:mod:`.track`). The Lake Hald recording (Baktoft et al. 2017) is in the repository's
``data/lake-hald/`` (for the tests and the docs; not in the wheel)."""
