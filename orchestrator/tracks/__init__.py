"""Recorded tracks of a moving target: times of arrival at a fixed array of receivers (an inverted LBL) read as
hostile input (:mod:`.toa`), tracked by :mod:`sblsim.models.receiver.toa_tracking` and scored against a truth
track (:mod:`.score`). The Lake Hald recording (Baktoft et al. 2017) ships in ``data/lake-hald/``."""
