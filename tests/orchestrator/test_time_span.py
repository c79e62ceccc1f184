"""The times sblsim reads and writes span 1970 to 2262-04-11 (orchestrator/io/times.py), said as such."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.declarations import ModelError


def test_the_latest_time_is_told_as_it_is():
    """Issue 98 item 7: a date after pandas' 2262 limit was refused as 'a date that does not exist'; the span is now
    said, and the epoch form holds the same limit (numpy's datetime64[s] the independent count)."""
    from sblsim.orchestrator.io.times import MAX_EPOCH, TIME_SPAN, iso_utc, utc_seconds

    assert MAX_EPOCH == int(np.datetime64("2262-04-11T23:47:16", "s").astype(np.int64))
    assert iso_utc([MAX_EPOCH])[0] == "2262-04-11T23:47:16.000000Z"
    assert utc_seconds(["2262-04-11T23:47:16Z"], "t", [2], "end")[0] == MAX_EPOCH
    for late in ("2286-01-01", "2262-04-12 00:00:00", str(MAX_EPOCH + 1)):
        with pytest.raises(ModelError) as refused:
            utc_seconds([late], "receivers: 'r.csv'", [7], "recover_date_time")
        assert "line 7" in str(refused.value) and TIME_SPAN in str(refused.value)
    with pytest.raises(ModelError, match="exists"):
        utc_seconds(["2023-02-30"], "t", [3], "start")


def test_times_without_a_zone_read_by_arrow_as_pandas_reads_them():
    """Plain ISO times without a zone are parsed by Arrow's cast (ten times pandas' parse): on 2,000 random cells of
    every form (date alone, minutes, seconds, a fraction of 1 to 9 digits, ``T`` or a space, 1970 to 2261, 29 February
    of leap years) the seconds are pandas' own parse of the same cells, to the nanosecond; a cell Arrow refuses (a
    zone, a day or hour that does not exist, beyond 2262) goes to pandas, which reads or refuses it as before."""
    import pandas as pd

    from sblsim.orchestrator.io.times import _zoneless_nanoseconds, utc_seconds

    rng = np.random.default_rng(5)
    days = rng.integers(0, int(np.datetime64("2261-12-31", "D").astype(np.int64)), 2000)
    cells = []
    for k, day in enumerate(days):
        date = str(np.datetime64(int(day), "D"))
        form = k % 5
        clock = f"{rng.integers(24):02d}:{rng.integers(60):02d}"
        if form == 0:
            cells.append(date if k % 10 else "2024-02-29")
        elif form == 1:
            cells.append(f"{date}{'T' if k % 2 else ' '}{clock}")
        else:
            digits = "" if form == 2 else "." + "".join(map(str, rng.integers(10, size=rng.integers(1, 10))))
            cells.append(f"{date}{'T' if k % 2 else ' '}{clock}:{rng.integers(60):02d}{digits}")
    series = pd.Series(cells, dtype="str")
    assert _zoneless_nanoseconds(series) is not None  # the fast path taken
    expected = pd.to_datetime(series, format="ISO8601", utc=True).to_numpy(dtype="datetime64[ns]").astype(np.int64)
    whole, rest = np.divmod(expected, 1_000_000_000)
    got = utc_seconds(series, "t", list(range(2, 2002)), "time")
    np.testing.assert_array_equal(got, whole.astype(float) + rest / 1e9)
    zoned = ["2023-08-31 21:15:42+02:00", "2023-08-31T21:15:42Z", "2023-08-31 21:15:42-0500"]
    assert _zoneless_nanoseconds(pd.Series(zoned, dtype="str")) is None
    np.testing.assert_array_equal(utc_seconds(zoned, "t", [2, 3, 4], "time"),
                                  [1693509342.0, 1693516542.0, 1693534542.0])
    for bad in ("2023-08-31 24:00:00", "2023-08-31 23:59:60", "2023-02-29"):
        assert _zoneless_nanoseconds(pd.Series([bad], dtype="str")) is None
        with pytest.raises(ModelError, match="line 9 column time.*exists"):
            utc_seconds(["2023-08-31 00:00", bad], "t", [8, 9], "time")


@pytest.mark.parametrize("cell, spreadsheet", [("6/3/2024 0:01", True), ("03.06.2024 00:01:07", True),
                                               ("6/3/2024 12:01 PM", True), ("6/3/24", True),
                                               ("2024/06/03 00:01", False), ("June 3 2024", False)])
def test_a_spreadsheet_s_date_is_named_as_one(cell, spreadsheet):
    """A GLATOS extract opened in a spreadsheet and saved again holds its locale's dates (``6/3/2024 0:01``: the
    seconds dropped): refused as before, and said to be a spreadsheet's date, to give the file as exported; another
    form that is no ISO time is refused without it."""
    from sblsim.orchestrator.io.times import ALLOWED, SPREADSHEET_SAID, utc_seconds

    with pytest.raises(ModelError) as refused:
        utc_seconds(["2024-06-03 00:01:00.742", cell], "detections: 'd.csv'", [2, 3], "detection_timestamp_utc")
    said = str(refused.value)
    assert f"line 3 column detection_timestamp_utc: '{cell}' is not allowed" in said and ALLOWED in said, said
    assert said.endswith(SPREADSHEET_SAID) == spreadsheet and "\n" not in said
