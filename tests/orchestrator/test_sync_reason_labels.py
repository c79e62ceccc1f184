"""The sync's residuals name each arrival's ``reason`` by a code into six shared strings: the labels are those of the
conditions taken in their order (the first that holds), as nested ``numpy.where`` gives them, and a table of many
rows holds six string objects, not one a row."""

from __future__ import annotations

import numpy as np

from sblsim.orchestrator.sync.clock_tables import REASONS, _reasons


def test_the_codes_name_the_first_condition_that_holds_with_six_shared_strings():
    rng = np.random.default_rng(11)
    k = 20_000
    duplicate, single, broken, off, kept = (rng.random(k) < p for p in (0.1, 0.1, 0.1, 0.2, 0.7))
    got = _reasons(np.select([duplicate, single, broken, off, ~kept], [1, 2, 3, 4, 5], 0))
    want = np.where(duplicate, "multipath", np.where(single, "single receiver", np.where(
        broken, "clock break", np.where(off, "not synchronised", np.where(kept, "", "rejected")))))
    assert got.dtype == object and got.tolist() == want.tolist()
    assert set(got.tolist()) == set(REASONS)  # every label met on this many rows
    assert len({id(label) for label in got}) == len(REASONS)
