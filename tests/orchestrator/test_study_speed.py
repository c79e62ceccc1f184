"""The sound speed a study's synchronisation estimates from its sync tags, each tag's fallback where its own pings
cannot calibrate one (orchestrator/telemetry/study_clocks.py ``estimated_speed``, study_offsets.py ``study_speed``):
its σ the fit's, the survey's share through the array's scale (models/sync/survey_error.py ``scale_sigma``) and
calibration's MAX_SIGMA; scored against the simulated truth."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from sblsim.models.sync.survey_error import Z_SEEN
from sblsim.models.tracking.calibration import MAX_SIGMA
from sblsim.models.tracking.sound_speed import fallback_prior
from sblsim.orchestrator.sync.estimated_speed import estimated_speed
from sblsim.orchestrator.sync.survey_console import speed_sigma_text
from sblsim.orchestrator.telemetry.simulate import simulate_study
from sblsim.orchestrator.telemetry.study_clocks import SYNCHRONISED_HERE
from sblsim.orchestrator.telemetry.study_offsets import fitted_options, study_speed

WATER = 1480.0  # [m/s] the simulation's sound speed


def test_the_speed_a_synchronisation_estimated_and_its_sigma():
    """The fit's σ and the survey's share (the speed times the survey error taken times the scale's σ per metre) in
    quadrature; each receiver's survey error as their RMS, none taken the one seen or the test's bound; no σ where
    the scale or the survey error is not determined; nothing where the speed was given, taken from a series or has
    no σ; a tag's options carry it with MAX_SIGMA in quadrature, for clocks synchronised here or given, not for
    clocks taken as logged, nor where its σ is not below the default's."""
    summary = {"sound_speed": {"source": "estimated", "sound_speed_m_s": 1476.8, "sound_speed_sigma_m_s": 0.3},
               "survey_sigma_m": 2.0, "survey_error": {"speed_scale_sigma_per_m": 0.001}}
    found = estimated_speed(summary)
    share = 1476.8 * 2.0 * 0.001
    assert found == pytest.approx({"sound_speed_m_s": 1476.8, "sound_speed_sigma_m_s": np.sqrt(0.09 + share**2),
                                   "sound_speed_survey_sigma_m_s": share})
    each = estimated_speed(summary | {"survey_sigma_m": {"a": 1.0, "b": 7.0}})
    assert each["sound_speed_survey_sigma_m_s"] == pytest.approx(1476.8 * 5.0 * 0.001)
    assert estimated_speed(summary | {"survey_sigma_m": 0.0})["sound_speed_sigma_m_s"] == pytest.approx(0.3)
    # none taken: the one seen, else what the residuals' test could have missed (Z_SEEN standard errors)
    unseen = {"seen": False, "survey_sigma_m": 0.0, "survey_sigma_se_m": 0.05, "speed_scale_sigma_per_m": 0.001}
    bound = estimated_speed(summary | {"survey_sigma_m": None, "survey_error": unseen})
    assert bound["sound_speed_survey_sigma_m_s"] == pytest.approx(1476.8 * Z_SEEN * 0.05 * 0.001)
    shown = estimated_speed(summary | {"survey_sigma_m": None, "survey_error": unseen | {"seen": True,
                                                                                        "survey_sigma_m": 1.5}})
    assert shown["sound_speed_survey_sigma_m_s"] == pytest.approx(1476.8 * 1.5 * 0.001)
    # the scale or the survey error not determined (too few pairs): the speed said, its σ None, not taken
    for undetermined in (summary | {"survey_error": None}, summary | {"survey_sigma_m": None, "survey_error": None},
                         summary | {"survey_error": {"speed_scale_sigma_per_m": None}}):
        said = estimated_speed(undetermined)
        assert said["sound_speed_m_s"] == 1476.8 and said["sound_speed_sigma_m_s"] is None
        assert study_speed({"source": SYNCHRONISED_HERE} | said) is None
        assert "not bounded" in speed_sigma_text(said, 0.3) and not speed_sigma_text(said, 0.3).startswith(", σ")
    for source in ("given", "series"):
        assert estimated_speed(summary | {"sound_speed": {"source": source, "sound_speed_m_s": 1480.0}}) == {}
    assert estimated_speed(summary | {"sound_speed": summary["sound_speed"] | {"sound_speed_sigma_m_s": None}}) == {}
    info = {"source": SYNCHRONISED_HERE} | found
    speed = (1476.8, float(np.hypot(found["sound_speed_sigma_m_s"], MAX_SIGMA)))
    assert study_speed(info) == pytest.approx(speed) and fitted_options(info, True)["study_speed"] == speed
    assert study_speed(info | {"source": "given"}) == pytest.approx(speed)
    logged = info | {"source": "as logged"}
    assert study_speed(logged) is None and fitted_options(logged, True) == {}
    default = fallback_prior()[1]  # a σ not below the default's: the default taken (the study's tells no more)
    assert study_speed(info | {"sound_speed_sigma_m_s": np.sqrt(default**2 - MAX_SIGMA**2) * 1.001}) is None
    assert study_speed(info | {"sound_speed_sigma_m_s": np.sqrt(default**2 - MAX_SIGMA**2) * 0.999}) is not None


def _study(tmp_path, seed: int, moved: float = 0.0, receivers: int = 4, tags: int = 3, days: float = 0.25,
           water=WATER):
    """A simulated GLATOS study with its sync tags (``receivers``, ``tags`` animals, ``days``, the ``water``'s sound
    speed), each deployment's position off by ``moved`` [m per axis, σ], run through the CLI: the simulation, the
    study's folder and its ``study.json``."""
    from sblsim.orchestrator import cli

    sim = simulate_study(n_receivers=receivers, n_tags=tags, days=days, redeployed=0, seed=seed, offset=0.01,
                         drift=1e-7, sound_speed=water)
    files = sim.write(tmp_path / "in", "glatos")
    if moved:
        sheet = pd.read_csv(files["deployments"], dtype=str, keep_default_na=False)
        north, east = np.random.default_rng(99 + seed).normal(0.0, moved, (2, len(sheet)))
        lat = sheet["deploy_lat"].astype(float)
        sheet["deploy_lat"] = (lat + north / 111_320.0).map("{:.10f}".format)
        sheet["deploy_long"] = (sheet["deploy_long"].astype(float) + east / (111_320.0 * np.cos(np.radians(lat)))
                                ).map("{:.10f}".format)
        sheet.to_csv(files["deployments"], index=False)
    out = tmp_path / "study"
    assert cli.main(["track", str(files["detections"]), "--receivers", str(files["deployments"]), "--tags",
                     str(files["tags"]), "--out", str(out)]) == 0
    return sim, out, json.loads((out / "study.json").read_text())


def _errors(sim, out, reference: str) -> pd.DataFrame:
    """Each track row's error [m] against the simulated truth (on the reference receiver's clock) and its NEES."""
    tracks = pd.read_csv(out / "tracks.csv")
    deployment = int(np.flatnonzero(sim.clocks["serial"].astype(str) == reference)[0])
    parts = []
    for tag, rows in tracks.groupby("tag"):
        e = rows[["x", "y"]].to_numpy() - sim.truth_at(tag, rows["epoch_s"].to_numpy(), deployment)
        parts.append(pd.DataFrame({"tag": tag, "error": np.hypot(*e.T),
                                   "nees": (e[:, 0] / rows["sigma_x"]) ** 2 + (e[:, 1] / rows["sigma_y"]) ** 2}))
    return pd.concat(parts)


def test_a_tag_heard_by_four_receivers_takes_the_sync_tags_speed(tmp_path):
    """Four receivers with their sync tags, one animal (a ping heard by four: its own pings calibrate nothing): the
    tag takes the speed the synchronisation estimated (within 3 m/s of the water's here) as its fallback, not the
    default's 1,500 m/s."""
    sim, out, study = _study(tmp_path, 5, tags=1, days=0.15)
    clocks = study["clocks"]
    assert clocks["source"] == SYNCHRONISED_HERE and abs(clocks["sound_speed_m_s"] - WATER) < 3.0, clocks
    tags = pd.read_csv(out / "tags.csv")
    assert (tags["sound_speed_source"] == "fallback").all()
    assert np.allclose(tags["sound_speed_m_s"], clocks["sound_speed_m_s"]), tags["sound_speed_m_s"]


@pytest.mark.slow
def test_four_receivers_tracked_at_the_sync_tags_speed(tmp_path):
    """Four receivers with their sync tags, three animals, a quarter day: at the default's 1,500 m/s, 51 m/s
    uncertain, each tag was a median 0.53-0.75 m from the truth (σ 1.3-1.9 m, NEES 0.5-0.8; seeds 6 and 7 alike); at
    the sync tags' 1,479.7 m/s each is below 0.3 m (0.20-0.21 measured) with a NEES (2-D) in [1, 4.5] (1.9-2.2)."""
    sim, out, study = _study(tmp_path, 5)
    for tag, rows in _errors(sim, out, study["clocks"]["reference_receiver"]).groupby("tag"):
        assert rows["error"].median() < 0.3 and 1.0 <= rows["nees"].mean() <= 4.5, (tag, rows.describe())


@pytest.mark.slow
@pytest.mark.parametrize("seed", [5, 6, 7, 8, 10])
def test_the_sync_tags_speed_is_as_uncertain_as_the_survey_makes_it(tmp_path, seed):
    """Four receivers each off by 2 m per axis: the sync's speed takes the array's scale error (11-23 m/s off the
    water's on seeds 5-7, where the fit's own σ is below 1 m/s); its σ with the survey's share holds it within 2.5 σ
    (1.0-1.4 σ measured), and the tags, whose error the survey dominates, keep a NEES (2-D) in [0.3, 4.5] (0.4-3.5).
    Seeds 8 and 10: two of the twelve pairs set aside, the survey error not seen (its standard error 10¹¹-10¹² m) and
    the scale barely determined by the rest: the speed (52 and 14 m/s off, 10 and 2.8 of a σ that left the survey
    out) is said with a σ beyond the default's, not taken; each tag falls back on the default's."""
    sim, out, study = _study(tmp_path / str(seed), seed, moved=2.0)
    clocks = study["clocks"]
    if seed in (8, 10):
        sigma = clocks["sound_speed_sigma_m_s"]
        assert sigma is None or sigma > fallback_prior()[1], clocks
        tags = pd.read_csv(out / "tags.csv")
        assert (tags["sound_speed_source"] == "fallback").all() and np.allclose(tags["sound_speed_m_s"], 1500.0)
        return
    assert clocks["sound_speed_survey_sigma_m_s"] > 3.0 * np.sqrt(max(
        clocks["sound_speed_sigma_m_s"] ** 2 - clocks["sound_speed_survey_sigma_m_s"] ** 2, 0.0)), clocks
    assert abs(clocks["sound_speed_m_s"] - WATER) < 2.5 * np.hypot(clocks["sound_speed_sigma_m_s"], MAX_SIGMA), clocks
    for tag, rows in _errors(sim, out, clocks["reference_receiver"]).groupby("tag"):
        assert 0.3 <= rows["nees"].mean() <= 4.5, (tag, rows.describe())


def test_a_synchronisation_s_folder_given_gives_its_speed_as_one_made_here(tmp_path, capsys):
    """``sblsim sync`` on four receivers, its folder given to the study (``--sync DIR``): the clocks' speed and σ
    those of the study synchronised here, and its tag tracked at that speed (the same as there, to a millimetre
    per second); the sync's console says the speed's whole σ, the fit's and the survey's share (recomputed here
    from its ``sync.json``)."""
    from sblsim.orchestrator import cli

    sim = simulate_study(n_receivers=4, n_tags=1, days=0.15, redeployed=0, seed=5, offset=0.01, drift=1e-7)
    files = sim.write(tmp_path / "in", "glatos")
    assert cli.main(["sync", str(files["detections"]), "--receivers", str(files["deployments"]), "--out",
                     str(tmp_path / "sync")]) == 0
    said = capsys.readouterr().out.splitlines()[0]
    data = json.loads((tmp_path / "sync" / "sync.json").read_text())
    speed, seen = data["sound_speed"], data["survey_error"]
    survey = data.get("survey_sigma_m") or (seen["survey_sigma_m"] if seen["seen"]
                                            else Z_SEEN * seen["survey_sigma_se_m"])
    share = speed["sound_speed_m_s"] * survey * seen["speed_scale_sigma_per_m"]
    assert (f"sound speed {speed['sound_speed_m_s']:.1f} m/s (estimated), σ "
            f"{np.hypot(speed['sound_speed_sigma_m_s'], share):.2g} m/s (the fit's "
            f"{speed['sound_speed_sigma_m_s']:.2g}, the survey's share {share:.2g})") in said, said
    made = {}
    for name, extra in (("here", []), ("given", ["--sync", str(tmp_path / "sync")])):
        assert cli.main(["track", str(files["detections"]), "--receivers", str(files["deployments"]), "--tags",
                         str(files["tags"]), "--out", str(tmp_path / name), *extra]) == 0
        made[name] = (json.loads((tmp_path / name / "study.json").read_text())["clocks"],
                      pd.read_csv(tmp_path / name / "tags.csv"))
    (here, here_tags), (given, given_tags) = made["here"], made["given"]
    assert given["source"] == "given" and here["source"] == SYNCHRONISED_HERE
    for key in ("sound_speed_m_s", "sound_speed_sigma_m_s", "sound_speed_survey_sigma_m_s"):
        assert given[key] == pytest.approx(here[key], rel=1e-9), key
    assert (given_tags["sound_speed_source"] == "fallback").all()
    np.testing.assert_allclose(given_tags["sound_speed_m_s"], here_tags["sound_speed_m_s"], rtol=0, atol=1e-3)
    np.testing.assert_allclose(given_tags["sound_speed_m_s"], given["sound_speed_m_s"], rtol=0, atol=1e-9)


@pytest.mark.parametrize("field, value, says", [
    ("sound_speed_m_s", 1e9, "sound_speed.sound_speed_m_s: 1000000000.0 is outside the allowed range [1300, 1700] m/s"),
    ("sound_speed_sigma_m_s", "x", "sound_speed.sound_speed_sigma_m_s: 'x' is not a number"),
    ("speed_scale_sigma_per_m", -1.0,
     "survey_error.speed_scale_sigma_per_m: -1.0 is outside the allowed range [0, 1] 1/m"),
    ("survey_sigma_m", {"a": 1e6}, "survey_sigma_m['a']: 1000000.0 is outside the allowed range [0, 1000] m"),
])
def test_a_folder_s_speed_out_of_its_range_is_refused_in_one_line(tmp_path, field, value, says):
    """A ``sync.json`` whose speed's numbers are not numbers or outside their ranges is refused naming the field
    and the range (never taken as a tag's prior); one that estimated none gives nothing."""
    from sblsim.models.declarations import ModelError
    from sblsim.orchestrator.telemetry.study_clocks import folder_speed

    data = {"sound_speed": {"source": "estimated", "sound_speed_m_s": 1476.8, "sound_speed_sigma_m_s": 0.3},
            "survey_sigma_m": 2.0, "survey_error": {"speed_scale_sigma_per_m": 0.001}}
    (tmp_path / "sync.json").write_text(json.dumps(data))
    assert folder_speed(tmp_path)["sound_speed_sigma_m_s"] == pytest.approx(np.hypot(0.3, 1476.8 * 2.0 * 0.001))
    bad = json.loads(json.dumps(data))
    if field.startswith("sound_speed"):
        bad["sound_speed"][field] = value
    elif field == "speed_scale_sigma_per_m":
        bad["survey_error"][field] = value
    else:
        bad[field] = value
    (tmp_path / "sync.json").write_text(json.dumps(bad))
    with pytest.raises(ModelError, match="sync.json") as refused:
        folder_speed(tmp_path)
    assert says in str(refused.value) and "\n" not in str(refused.value)
    (tmp_path / "sync.json").write_text(json.dumps(data | {"sound_speed": {"source": "given",
                                                                             "sound_speed_m_s": 1480.0}}))
    assert folder_speed(tmp_path) == {}
    (tmp_path / "sync.json").unlink()
    assert folder_speed(tmp_path) == {}


def test_a_season_s_windows_rescale_each_tag_s_arrivals_to_the_season_s_speed():
    """``season_series``: each window's middle and speed where the windows' spread is above 0 (nothing where they
    agree), its σ the windows' largest and the survey's share in quadrature; a tag's options carry the series with
    the study's speed at that σ (and MAX_SIGMA). ``season_rescaled``: pings from four receivers in water whose speed
    runs linearly between two windows' middles, rescaled to the season's speed, are the times of arrival that speed
    would give (each ping's own emission and distances, against a computation here), to a few microseconds."""
    from sblsim.orchestrator.sync.estimated_speed import season_series
    from sblsim.orchestrator.tracks.speed import season_rescaled

    origin = 1.7e9
    summary = {"sound_speed": {"windows_spread_m_s": 9.0},
               "windows": {"edges": [origin, origin + 1000.0, origin + 3000.0], "sound_speed_m_s": [1470.0, 1480.0],
                           "sound_speed_sigma_m_s": [0.05, 0.12]}}
    found = season_series(summary, 0.5)
    assert found["sound_speed_windows"] == [[origin + 500.0, 1470.0], [origin + 2000.0, 1480.0]]
    assert found["sound_speed_windows_sigma_m_s"] == pytest.approx(np.hypot(0.12, 0.5))
    assert season_series(summary | {"sound_speed": {"windows_spread_m_s": 0.0}}, 0.5) == {}
    info = {"source": SYNCHRONISED_HERE, "sound_speed_m_s": 1475.0, "sound_speed_sigma_m_s": 7.0} | found
    options = fitted_options(info, True)
    assert options["study_speed"] == pytest.approx((1475.0, np.hypot(np.hypot(0.12, 0.5), MAX_SIGMA)))
    assert options["study_speed_series"] == found["sound_speed_windows"]
    assert "study_speed_series" not in fitted_options({"source": SYNCHRONISED_HERE, "sound_speed_m_s": 1475.0,
                                                       "sound_speed_sigma_m_s": 7.0}, True)
    rng = np.random.default_rng(1)
    receivers = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 200.0], [0.0, 200.0]])
    places = rng.uniform(20.0, 180.0, (40, 2))
    emitted = np.sort(rng.uniform(500.0, 2000.0, 40))
    water = 1470.0 + (emitted - 500.0) / 1500.0 * 10.0  # linear between the middles, as the series is
    distance = np.linalg.norm(places[:, None, :] - receivers[None], axis=2)
    toa = emitted[:, None] + distance / water[:, None]
    scaled, said = season_rescaled(toa, receivers, found["sound_speed_windows"], origin, 1475.0, 1e-4)
    np.testing.assert_allclose(scaled, emitted[:, None] + distance / 1475.0, rtol=0, atol=5e-6)
    assert said["windows"] == 2 and said["season_m_s"] == 1475.0
    assert said["range_m_s"] == pytest.approx([water.min(), water.max()], abs=0.01)


@pytest.mark.slow
def test_a_season_whose_water_changes_is_tracked_nearly_as_one_whose_water_does_not(tmp_path):
    """Three simulated weeks of six receivers, two animals, in water running 1,470 → 1,500 → 1,470 m/s against the
    same weeks in water at its mean (1,485 m/s): each tag's arrivals rescaled by the synchronisation's three windows'
    speeds (``summary.json``'s ``sound_speed.season_windows``), its median error within 1.5 times the steady water's
    (twice it with one speed for the season), NEES in [1, 4.5]."""
    span = 21 * 86400.0
    medians = {}
    for name, water in (("steady", 1485.0), ("changing", lambda t: 1485.0 - 15.0 * np.cos(2 * np.pi * t / span))):
        sim, out, study = _study(tmp_path / name, 5, receivers=6, tags=2, days=21.0, water=water)
        for tag, rows in _errors(sim, out, study["clocks"]["reference_receiver"]).groupby("tag"):
            medians[name, tag] = rows["error"].median()
            said = json.loads((out / "tags" / tag / "summary.json").read_text())["sound_speed"]
            assert ("season_windows" in said) == (name == "changing"), said
            if name == "changing":
                assert said["season_windows"]["windows"] == 3
                assert 1.0 <= rows["nees"].mean() <= 4.5, (tag, rows.describe())
    for (name, tag), median in medians.items():
        if name == "changing":
            assert median <= 1.5 * medians["steady", tag], medians


@pytest.mark.parametrize("change, says", [
    (None, None),
    ({"edges": [1.7e9 + 1000.0, 1.7e9, 1.7e9 + 3000.0]}, "windows.edges: not increasing"),
    ({"sound_speed_m_s": [1470.0, 1e9]}, "windows.sound_speed_m_s: 1000000000.0 is outside the allowed range"),
    ({"sound_speed_sigma_m_s": [0.05]}, "2 speeds and 1 sigmas"),
    ({"edges": [1.7e9 + k for k in range(20_002)]}, "at most 10000 windows"),
])
def test_a_folder_s_season_windows_are_taken_as_one_made_here_or_refused(tmp_path, change, says):
    """A synchronisation's folder of a season whose windows' speeds differ (``sync.json``'s ``windows`` and
    ``sound_speed.windows_spread_m_s``) gives each tag the same windows' series and σ as
    :func:`~sblsim.orchestrator.sync.estimated_speed.estimated_speed` gives a study synchronised here from the same
    summary; its windows' numbers out of their ranges refused in one line naming the field."""
    from sblsim.models.declarations import ModelError
    from sblsim.orchestrator.telemetry.study_clocks import folder_speed

    windows = {"edges": [1.7e9, 1.7e9 + 1000.0, 1.7e9 + 3000.0], "sound_speed_m_s": [1470.0, 1480.0],
               "sound_speed_sigma_m_s": [0.05, 0.12], "count": 2}
    data = {"sound_speed": {"source": "estimated", "sound_speed_m_s": 1475.0, "sound_speed_sigma_m_s": 5.0,
                            "windows_spread_m_s": 7.0},
            "survey_sigma_m": 1.0, "survey_error": {"speed_scale_sigma_per_m": 0.001}, "windows": windows}
    bad = json.loads(json.dumps(data))
    bad["windows"] |= change or {}
    (tmp_path / "sync.json").write_text(json.dumps(bad, indent=1))  # (as sblsim writes it: a number a line)
    if says is None:
        found, made = folder_speed(tmp_path), estimated_speed(data)
        assert found.keys() == made.keys() and len(found["sound_speed_windows"]) == 2
        for key, value in made.items():
            assert np.asarray(found[key]) == pytest.approx(np.asarray(value), rel=1e-12), key
        return
    with pytest.raises(ModelError, match="sync.json") as refused:
        folder_speed(tmp_path)
    assert says in str(refused.value) and "\n" not in str(refused.value)
