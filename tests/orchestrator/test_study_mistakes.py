"""Tried as a telemetry user would (issue 87's done-means): a simulated study (:mod:`sblsim.orchestrator.telemetry
.simulate`, a tag of each ping type) whose detections carry a receiver's clock reset (set back 20 s at a download,
the file sorted by time as an export is), stray detections 3 % of the detections (one receiver's false decodes of
the animals' ids, at random times) and a thin sync array (sync tags at 3 of 9 receivers), run by ``sblsim.track``
against the same study without the mistakes: every tag tracked, the reset named in one line with its size, every
stray row set aside and every real ping kept, the tracks against the simulated truth near the clean study's and
their stated uncertainty consistent with their errors (2-D NEES). And a deployment's sync-tag cell naming a tag no
receiver heard (an ID mistyped) said in the study's notes."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.orchestrator.telemetry.simulate import simulate_study, vue_text
from tests.helpers import check_tag_rows

SYNC_KEPT = 3
RESET_S = -20.0
STRAY_SHARE = 0.03


def _run(folder, mistakes: bool):
    sim = simulate_study(n_receivers=9, n_tags=3, days=0.25, redeployed=0, seed=5)
    files = sim.write(folder, "vue")
    rng = np.random.default_rng(11)
    d = sim.detections.copy()
    serials = sorted(d["serial"].unique())
    victim = serials[4]
    if mistakes:
        keep = set(rng.choice(len(serials), SYNC_KEPT, replace=False).tolist())
        gone = [t for k, t in enumerate(sim.deployments["transmitter"]) if k not in keep]
        sim.deployments.assign(transmitter=[t if k in keep else "" for k, t in
                                            enumerate(sim.deployments["transmitter"])]).to_csv(
            files["deployments"], index=False, float_format="%.10f")
        sim.sheet[~sim.sheet["transmitter"].isin(gone)].to_csv(files["tags"], index=False)
        d = d[~d["transmitter"].isin(gone)]
        d.loc[(d["serial"] == victim) & (d["time"] > d["time"].min() + 3 * 3600), "time"] += RESET_S
        strays = []
        for tag in sim.truth:
            n = int(STRAY_SHARE * (d["transmitter"] == tag).sum())
            strays.append(pd.DataFrame({"serial": rng.choice(serials, n), "model": "VR2AR", "transmitter": tag,
                                        "time": rng.uniform(d["time"].min(), d["time"].max(), n)}))
        d = pd.concat([d, *strays]).sort_values("time", kind="stable")
    files["detections"].write_text(vue_text(d.reset_index(drop=True)))
    result = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"],
                          out=folder / "out", workers=1)
    check_tag_rows(result.tags, result.tracks)
    return sim, result, victim


def _scores(sim, result):
    """Each tag's 2-D errors [m] and NEES against the truth read on the reference receiver's clock (its rows ok)."""
    reference = result.summary["clocks"]["reference_receiver"]
    k = int(np.flatnonzero(result.receivers["receiver"].to_numpy() == reference)[0])
    out = {}
    for tag, rows in result.tracks.groupby("tag"):
        rows = rows[rows["quality"] == "ok"]
        dx, dy = (rows[["x", "y"]].to_numpy() - sim.truth_at(tag, rows["epoch_s"].to_numpy(), k)).T
        out[tag] = (np.hypot(dx, dy), (dx / rows["sigma_x"]) ** 2 + (dy / rows["sigma_y"]) ** 2)
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mistakes")
    return _run(folder / "clean", False), _run(folder / "mistakes", True)


@pytest.mark.slow
def test_every_tag_tracked_and_the_reset_named_in_one_line(runs):
    _, (_, result, victim) = runs
    assert (result.tags["status"] == "tracked").all() and len(result.tags) == 3
    breaks = result.summary["clocks"]["clock_breaks"]
    assert [b["receiver"] for b in breaks] == [victim]
    assert breaks[0]["size_s"] == pytest.approx(RESET_S, abs=5e-3)
    said = [n for n in result.summary["notes"] if n.startswith("clock break")]
    assert len(said) == 1 and f"receiver {victim} went back 19.99" in said[0] and "\n" not in said[0]


@pytest.mark.slow
def test_every_stray_row_set_aside_and_every_ping_kept(runs):
    (_, clean, _), (_, result, _) = runs
    before = clean.tags.set_index("tag")
    after = result.tags.set_index("tag")
    for tag in after.index:
        # the clean study's pings are all positioned again; every row beyond them (a stray heard alone) set aside
        assert after.loc[tag, "positioned"] == before.loc[tag, "positioned"], tag
        assert after.loc[tag, "set_aside"] == after.loc[tag, "pings"] - before.loc[tag, "pings"] > 0, tag


@pytest.mark.slow
def test_the_tracks_near_the_clean_study_s_and_consistent(runs):
    (sim, clean, _), (_, result, _) = runs
    before, after = _scores(sim, clean), _scores(sim, result)
    for tag in after:
        rms = np.sqrt(np.mean(after[tag][0] ** 2))
        assert rms < 1.3 * np.sqrt(np.mean(before[tag][0] ** 2)) and rms < 0.5, tag
    nees = np.concatenate([after[tag][1] for tag in after])
    assert 1.0 <= nees.mean() <= 3.0, nees.mean()  # 2-D: 2 expected


def test_a_sync_tag_nobody_heard_is_said(tmp_path):
    """A deployment's sync-tag cell naming a tag no receiver heard (an ID mistyped: its last digit wrong) is said in
    the study's notes, the console's ``note:`` lines, by its name as the deployments give it; the tags are tracked
    on the other sync tags' clocks."""
    sim = simulate_study(n_receivers=5, n_tags=1, days=0.05, redeployed=0, seed=2)
    files = sim.write(tmp_path, "vue")
    given = sim.deployments["transmitter"].iloc[2]
    typo = given[:-1] + "9"  # A69-1601-60002 as A69-1601-60009: five sync tags, 60000 to 60004
    assert typo not in set(sim.detections["transmitter"])
    sim.deployments.assign(transmitter=sim.deployments["transmitter"].replace(given, typo)).to_csv(
        files["deployments"], index=False, float_format="%.10f")
    result = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], workers=1)
    said = [n for n in result.summary["notes"] if n.startswith("sync tags never heard")]
    assert said == [f"sync tags never heard: {typo}"]
    assert result.summary["clocks"]["source"] == "synchronised here"
    assert (result.tags["status"] == "tracked").all()
