"""``sblsim sync``'s figures' tables (:mod:`sblsim.orchestrator.sync.outputs`) from the columns' codes: the same as
a frame of the kept rows grouped by their texts (pandas, in the test)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from sblsim.orchestrator.sync.outputs import _kept_by_receiver


def test_the_kept_residuals_by_receiver_and_pair_are_the_grouped_texts():
    """Receivers and tags as Arrow's strings (a table read back from Parquet) and as Python's, a receiver with no
    kept arrival: each receiver's residuals in the rows' order and each pair's count as the texts' groupby has them,
    no receiver without a kept arrival drawn."""
    rng = np.random.default_rng(4)
    n = 5000
    frame = pd.DataFrame({"receiver": rng.choice(["R10", "R2", "R7", "Rnone"], n),
                          "tag": rng.choice(["A69-1601-9", "A69-1601-10", "A69-1601-11"], n),
                          "residual_m": rng.normal(0.0, 0.3, n), "kept": rng.random(n) < 0.8})
    frame.loc[frame["receiver"] == "Rnone", "kept"] = False
    kept = frame[frame["kept"]]
    expected = {r: g.to_numpy() for r, g in kept.groupby("receiver")["residual_m"]}
    counts = {k: int(v) for k, v in kept.groupby(["tag", "receiver"]).size().items()}
    for texts in (frame, frame.astype({"receiver": object, "tag": object})):
        drawn, pairs = _kept_by_receiver(texts)
        assert sorted(drawn) == sorted(expected) == ["R10", "R2", "R7"]
        assert all(np.array_equal(drawn[r], expected[r]) for r in expected)
        assert pairs == counts and sum(pairs.values()) == len(kept)
