"""A truth as logged (issue 97 item 5): a track whose time column holds epoch seconds under a plain name (``t``,
``time``) is taken on the times of arrival's base where their origin is known (``replay --format detections`` and
``toa`` know it: orchestrator/readers/time_series.py), as the same track on that base is."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.time_series import EPOCH_MARGIN, read_track

ORIGIN = 1568052000.0


def _write(path, times, name="t"):
    rows = "".join(f"{float(t)!r},{10.0 + k},{-5.0 - k}\n" for k, t in enumerate(times))
    path.write_text(f"{name},x,y\n" + rows)
    return path


@pytest.mark.parametrize("name", ["t", "time", "time_s"])
def test_epoch_seconds_under_a_plain_name_are_taken_to_the_base(tmp_path, name):
    relative = np.array([138.25, 140.5, 4299.75])
    logged = read_track(_write(tmp_path / "gps.csv", ORIGIN + relative, name), "truth", origin=ORIGIN)
    based = read_track(_write(tmp_path / "based.csv", relative, name), "truth", origin=ORIGIN)
    assert np.allclose(logged, based, rtol=0, atol=1e-6) and np.allclose(logged[:, 0], relative, atol=1e-6)


def test_numbers_on_the_base_stay_and_without_an_origin_nothing_is_guessed(tmp_path):
    relative = np.array([0.5, 10.0, 20.0])
    assert np.allclose(read_track(_write(tmp_path / "a.csv", relative), "truth", origin=ORIGIN)[:, 0], relative)
    logged = ORIGIN + relative
    assert np.allclose(read_track(_write(tmp_path / "b.csv", logged), "truth")[:, 0], logged)  # no origin: as is
    early = np.array([ORIGIN - 2 * EPOCH_MARGIN, ORIGIN + 5.0])  # a day and more before the origin: not epoch
    assert np.allclose(read_track(_write(tmp_path / "c.csv", early), "truth", origin=ORIGIN)[:, 0], early)
    with pytest.raises(ModelError, match="does not increase|increas"):
        read_track(_write(tmp_path / "d.csv", ORIGIN + np.array([5.0, 1.0, 9.0])), "truth", origin=ORIGIN)
