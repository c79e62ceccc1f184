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
