"""The survey error a synchronisation's residuals show, from its tables (orchestrator/sync/survey_seen.py): the
pairs against a loop over the rows, the estimate against the model's function on pairs made here, the console's
line; and a synchronisation of simulated sync tags on positions as they are and off by a known error (slow)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sblsim.models.sync.survey_error import MIN_PAIR_ARRIVALS, survey_error
from sblsim.orchestrator.sync.survey_console import survey_line
from sblsim.orchestrator.sync.survey_seen import pairs, seen_in_fit, seen_survey_error

POSITIONS = np.array([[0.0, 0.0], [300.0, 0.0], [300.0, 250.0], [0.0, 250.0], [150.0, 120.0], [60.0, 200.0]])
NAMES = [f"R{j}" for j in range(len(POSITIONS))]


def _residuals(seed: int = 0, sigma: float = 1.0) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """A synchronisation's tables: a sync tag at R0, R2 and R4, each heard at every receiver; its arrivals' residuals
    the table's positions' error along each pair plus noise; some set aside, some at the tag's own receiver, one pair
    with too few arrivals."""
    rng = np.random.default_rng(seed)
    delta = sigma * rng.normal(size=POSITIONS.shape)
    rows = []
    for t, h in enumerate((0, 2, 4)):
        for k in range(len(POSITIONS)):
            d = POSITIONS[k] - POSITIONS[h]
            distance = float(np.linalg.norm(d))
            along = 0.0 if k == h else float(d @ (delta[k] - delta[h])) / distance
            n = 5 if (t, k) == (1, 3) else int(rng.integers(20, 60))
            for _ in range(n):
                rows.append({"receiver": NAMES[k], "tag": f"S{h}", "distance_m": distance,
                             "residual_m": along + 0.3 * rng.normal(), "kept": bool(rng.random() > 0.1)})
    residuals = pd.DataFrame(rows)
    sync_tags = pd.DataFrame({"tag": ["S0", "S2", "S4"], "receiver": ["R0", "R2", "R4"]})
    receivers = pd.DataFrame({"receiver": NAMES, "x": POSITIONS[:, 0], "y": POSITIONS[:, 1]})
    return residuals, sync_tags, receivers


@pytest.mark.parametrize("rejected", [False, True])
def test_the_pairs_are_each_receiver_and_tags_kept_arrivals_at_a_distance(rejected):
    residuals, _, _ = _residuals()
    found = pairs(residuals, rejected)
    keys = list(zip(found["receiver"], found["tag"]))
    assert keys == sorted(keys)  # in the texts' order, as a groupby on them gives it
    table = found.set_index(["receiver", "tag"])
    expected = {}
    for (receiver, tag), rows in residuals.groupby(["receiver", "tag"]):
        r = rows.loc[(rows["kept"] | rejected) & (rows["distance_m"] > 0), "residual_m"].to_numpy()
        if len(r) >= MIN_PAIR_ARRIVALS:
            expected[(receiver, tag)] = (np.median(r), len(r), 1.4826 * np.median(np.abs(r - np.median(r))))
    assert set(table.index) == set(expected) and ("R3", "S2") not in expected and ("R0", "S0") not in expected
    for key, (median, count, scale) in expected.items():
        assert table.loc[key, "median"] == pytest.approx(median) and table.loc[key, "count"] == count
        assert table.loc[key, "scale"] == pytest.approx(scale)


@pytest.mark.parametrize("seed", range(4))
def test_the_pairs_figures_are_pandas_group_medians_to_the_bit(seed):
    """The pairs' medians, counts and scales as pandas' group-by on the texts makes them (group median and size,
    the deviations from each row's group median): equal to the bit, with residuals missing (NaN, counted, not in the
    figures), rounded ones (ties) and groups of even and odd sizes."""
    rng = np.random.default_rng(seed)
    n = 3000
    residuals = pd.DataFrame({"receiver": rng.choice(NAMES, n), "tag": rng.choice(["S0", "S2", "S4"], n),
                              "distance_m": rng.choice([0.0, 150.0, 300.0], n),
                              "residual_m": rng.normal(size=n).round(int(rng.integers(1, 4))),
                              "kept": rng.random(n) > 0.2})
    residuals.loc[rng.random(n) < 0.05, "residual_m"] = np.nan
    found = pairs(residuals)
    rows = residuals[residuals["kept"] & (residuals["distance_m"] > 0)]
    groups = rows.groupby(["receiver", "tag"])["residual_m"]
    median = groups.transform("median")
    expected = pd.DataFrame({"median": groups.median(), "count": groups.size(),
                             "scale": 1.4826 * (rows["residual_m"] - median).abs().groupby(
                                 [rows["receiver"], rows["tag"]]).median()})
    expected = expected[expected["count"] >= MIN_PAIR_ARRIVALS].reset_index()
    assert (found["count"] % 2 == 0).any() and (found["count"] % 2 == 1).any()
    pd.testing.assert_frame_equal(found[["receiver", "tag", "median", "count", "scale"]], expected,
                                  check_exact=True, check_dtype=False)


def test_the_estimate_is_the_models_on_the_pairs():
    residuals, sync_tags, receivers = _residuals(1, sigma=2.0)
    found = seen_survey_error(residuals, sync_tags, receivers)
    table = pairs(residuals, rejected=True)
    home = table["tag"].str[1:].astype(int).to_numpy()
    listener = table["receiver"].str[1:].astype(int).to_numpy()
    tags = {"S0": 0, "S2": 1, "S4": 2}
    direct = survey_error(table["median"].to_numpy(), table["count"].to_numpy(), table["scale"].to_numpy(),
                          listener, home, table["tag"].map(tags).to_numpy(), POSITIONS)
    assert found == direct and found.pairs == len(table) and found.seen
    assert seen_survey_error(residuals.assign(residual_m=np.nan), sync_tags, receivers) is None
    # the arrivals the fit rejected count: the same estimate whatever their kept flag
    assert seen_survey_error(residuals.assign(kept=False), sync_tags, receivers) == found


def test_the_console_line_says_what_was_seen_and_what_to_do():
    seen = {"survey_sigma_m": 3.02, "survey_sigma_se_m": 0.62, "excess_z": 40.0, "seen": True, "pairs": 70,
            "degrees": 45, "z_seen": 3.0}
    line = survey_line(seen, None)
    assert "3.02 ± 0.62 m per axis (70 pairs" in line and "--survey-sigma 3.02" in line
    assert survey_line(seen, 1.0).endswith("stated: 1 m)")
    assert "70 pairs of a sync tag and a receiver, 8 set aside as a path too long" in survey_line(
        seen | {"pairs_set_aside": 8}, None)
    unseen = seen | {"survey_sigma_m": 0.0, "excess_z": 1.2, "seen": False}
    assert "not seen" in survey_line(unseen, None) and "1.2 standard deviations, below 3" in survey_line(unseen, None)
    assert survey_line(None, None) is None and survey_line(seen | {"pairs": 0}, None) is None


@pytest.mark.slow
def test_a_synchronisation_sees_positions_off_and_not_positions_right():
    """Sync tags at 8 receivers over 6 hours (the simulator of models/sync/simulate.py), synchronised on the true
    positions (not seen) and on positions off by N(0, 2 m) per axis (seen, σ within [1, 3.5] m, said in sync.json's
    ``survey_error``)."""
    from sblsim.models.sync.simulate import simulate_sync
    from sblsim.orchestrator.readers.detections import Detections
    from sblsim.orchestrator.sync.run import synchronise

    sim = simulate_sync(n_receivers=8, hours=6.0, seed=3, noise=0.15e-3, echo_share=0.0)
    t = sim.time + 1_700_000_000
    frame = pd.DataFrame({"receiver": [f"R{j}" for j in sim.receiver], "tag": [f"S{i}" for i in sim.tag], "time": t,
                          "sensor_value": np.nan, "sensor_unit": "", "line": np.arange(len(t)) + 2})
    names = [f"R{j}" for j in range(8)]
    off = sim.positions[:, :2] + 2.0 * np.random.default_rng(7).normal(size=(8, 2))
    found, outcomes = {}, {}
    for label, xy in (("right", sim.positions[:, :2]), ("off", off)):
        hydrophones = pd.DataFrame({"receiver": names, "sync_tag": [f"S{j}" for j in range(8)], "x": xy[:, 0],
                                    "y": xy[:, 1], "z": np.nan})
        outcomes[label] = synchronise(Detections(frame, "simulated", "yaps"), hydrophones,
                                      sound_speed=sim.sound_speed, reference="R0")
        found[label] = outcomes[label].summary["survey_error"]
    assert not found["right"]["seen"] and found["right"]["survey_sigma_m"] == 0.0
    assert "survey_sigma_m" not in outcomes["right"].summary  # not seen: nothing taken, the positions exact
    assert found["off"]["seen"] and 1.0 <= found["off"]["survey_sigma_m"] <= 3.5, found["off"]
    # seen and none stated: taken as the survey's, the sync tags scored as with it stated (and not as with 0)
    taken = outcomes["off"].summary
    assert taken["survey_sigma_from"] == "seen" and taken["survey_sigma_m"] == found["off"]["survey_sigma_m"]
    hydrophones = pd.DataFrame({"receiver": names, "sync_tag": [f"S{j}" for j in range(8)], "x": off[:, 0],
                                "y": off[:, 1], "z": np.nan})
    for stated in (taken["survey_sigma_m"], 0.0):
        again = synchronise(Detections(frame, "simulated", "yaps"), hydrophones, sound_speed=sim.sound_speed,
                            reference="R0", survey_sigma=stated)
        assert again.summary["survey_sigma_from"] == "stated" and again.summary["survey_error"] == found["off"]
        same = np.allclose(again.sync_tags["nees_mean"], outcomes["off"].sync_tags["nees_mean"])
        assert same == (stated > 0), stated
        assert np.allclose(again.sync_tags["median_error_m"], outcomes["off"].sync_tags["median_error_m"])


def test_the_fits_arrays_give_what_its_tables_give():
    """:func:`seen_in_fit` on the arrivals' codes and residuals (before a synchronisation's tables are made) is
    :func:`seen_survey_error` on the same arrivals as tables."""
    residuals, sync_tags, receivers = _residuals(2, sigma=2.0)
    tag_names = ["S0", "S2", "S4"]
    receiver = residuals["receiver"].map(NAMES.index).to_numpy()
    tag = residuals["tag"].map(tag_names.index).to_numpy()
    residual = residuals["residual_m"].to_numpy(float).copy()
    residual[::7] = np.nan  # arrivals without a residual: in neither
    found = seen_in_fit(receiver, tag, residual, residuals["distance_m"].to_numpy(float), NAMES, tag_names,
                        np.array([0, 2, 4]), POSITIONS)
    assert found == seen_survey_error(residuals.assign(residual_m=residual), sync_tags, receivers)
    assert found.seen and found.pairs > 0


def test_the_console_line_says_where_the_error_seen_was_taken():
    seen = {"survey_sigma_m": 2.41, "survey_sigma_se_m": 0.47, "excess_z": 12.0, "seen": True, "pairs": 70,
            "degrees": 45, "z_seen": 3.0}
    taken = survey_line(seen, 2.41, "seen")
    assert "2.41 ± 0.47 m per axis" in taken and "taken as the survey's error in every σ" in taken
    assert "0 the positions as exact, --refine-positions refines them" in taken
    assert survey_line(seen, 0.0, "stated").endswith("stated: 0 m (the positions taken as exact))")
    assert survey_line(seen, 1.0, "stated").endswith("stated: 1 m)")
    refined = survey_line(seen, None, "refined")  # a study whose positions are refined next: not taken
    assert "not taken: --refine-positions refines the positions" in refined and "taken as" not in refined
