"""A true reason for every tag, found first (issue 96 item 5): on arrays that cannot position, each tag of a study
(``sblsim.track``) is a row of ``tags.csv`` saying why with its counts, computed here from the detections as written:
one receiver (its sync tag beside it: no synchronisation to make), a gate line across a river (receivers 400 m
apart, each hearing 350 m: 2 at once at most), whole-second times on clocks nobody synchronised; a tag sheet's
interval blamed only where the pings heard by 3 receivers at once contradict it (a receiver's stray codes do not),
and a refusal naming only what ``sblsim track`` takes (the tag sheet, not ``sblsim toa``'s ``--ping-type``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.frames import Frame, utm_zone
from sblsim.orchestrator.io.times import iso_utc, parse_instant
from sblsim.orchestrator.telemetry.simulate import SYNC_SPACE, simulate_study, vue_text
from tests.helpers import check_tag_rows

SPEED = 1480.0


def _without_sync(sim, folder, time=None):
    """The simulated study written with no sync tag (the deployments' transmitter blank, the sync tags'
    detections gone), the animals' detections' times ``time`` where given; its files."""
    files = sim.write(folder, "vue")
    sim.deployments.assign(transmitter="").to_csv(files["deployments"], index=False, float_format="%.10f")
    sim.sheet[sim.sheet["role"] == "animal"].to_csv(files["tags"], index=False)
    d = sim.detections[~sim.detections["transmitter"].str.startswith(SYNC_SPACE)]
    if time is not None:
        d = d.assign(time=time(d["time"].to_numpy()))
    files["detections"].write_text(vue_text(d.reset_index(drop=True)))
    return files, d


def _given(files):
    return [str(p) for p in files.values()]


def test_one_receiver_with_its_sync_tag(tmp_path):
    """One receiver of a simulated study, its own sync tag in the sheet: nothing to synchronise it against (said),
    and every tag heard by 1 receiver, its detections counted."""
    sim = simulate_study(n_receivers=9, n_tags=3, days=0.25, redeployed=0, seed=3)
    files = sim.write(tmp_path, "vue")
    serial = sim.deployments["ins_serial_no"].iloc[4]
    sim.deployments[sim.deployments["ins_serial_no"] == serial].to_csv(files["deployments"], index=False,
                                                                       float_format="%.10f")
    mine = sim.detections[sim.detections["serial"] == serial]
    files["detections"].write_text(vue_text(mine.reset_index(drop=True)))
    result = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], workers=1)
    check_tag_rows(result.tags, result.tracks, _given(files))
    assert result.summary["clocks"]["source"] == "as logged (one receiver)"
    counts = mine["transmitter"].value_counts()
    for row in result.tags.itertuples():
        assert row.status == "refused" and row.reason_code == "one_receiver"
        assert row.reason == (f"heard by 1 receiver ({serial}, {counts[row.tag]:,} detections): positioning needs 3 "
                              "at once")
        assert row.receivers == 1 and row.detections == counts[row.tag]


def _gate(folder, seed: int = 0):
    """A gate across a river: 4 receivers on a line 400 m apart, 3 tags over 2 hours, each pinging every 60 to 120 s,
    heard within 350 m (so by two receivers at most): the first crossing the line at one place (heard by the two
    receivers there), the others milling along it (heard by all four); the clocks synchronised already (no sync
    tag), times to the microsecond. Returns the files, the detections and each transmission's receivers."""
    rng = np.random.default_rng(seed)
    frame = Frame(utm_zone(56.2, 9.6))
    cx, cy = frame.from_latlon(np.array([56.2]), np.array([9.6]))
    receivers = np.c_[cx[0] + np.arange(4) * 400.0, np.full(4, cy[0])]
    serials = [str(470001 + k) for k in range(4)]
    start = parse_instant("2024-05-01T00:00:00Z", "start")
    lat, lon = frame.to_latlon(receivers[:, 0], receivers[:, 1])
    pd.DataFrame({"station": [f"G{k + 1}" for k in range(4)], "ins_serial_no": serials, "deploy_lat": lat,
                  "deploy_long": lon, "deploy_date_time": iso_utc([start - 86400.0] * 4),
                  "recover_date_time": iso_utc([start + 86400.0] * 4), "transmitter": ""}).to_csv(
        folder / "deployments.csv", index=False, float_format="%.10f")
    rows, heard = [], {}
    for k in range(3):
        tag = f"A69-1602-{2000 + k}"
        tau = np.cumsum(rng.uniform(60, 120, 80))
        x = cx[0] + (np.full(len(tau), rng.uniform(50, 350)) if k == 0 else np.linspace(0, 1200, len(tau)))
        where = np.c_[x, cy[0] + np.linspace(-300, 300, len(tau))]
        d = np.linalg.norm(where[:, None] - receivers[None], axis=2)
        e, j = np.nonzero(d < 350)
        heard[tag] = np.bincount(e, minlength=len(tau))
        rows.append(pd.DataFrame({"serial": np.array(serials)[j], "model": "VR2W", "transmitter": tag,
                                  "time": start + tau[e] + d[e, j] / SPEED + rng.normal(0, 1e-4, len(e))}))
    detections = pd.concat(rows).sort_values("time").reset_index(drop=True)
    (folder / "detections.csv").write_text(vue_text(detections))
    return {"detections": folder / "detections.csv", "deployments": folder / "deployments.csv"}, detections, heard


def test_a_gate_line_hears_two_at_once_at_most(tmp_path):
    files, detections, heard = _gate(tmp_path)
    assert max(h.max() for h in heard.values()) == 2  # the array as built: never three at once
    result = sblsim.track(files["detections"], receivers=files["deployments"], workers=1)
    check_tag_rows(result.tags, result.tracks, _given(files))
    assert len(result.tags) == 3 and result.tracks.empty
    for row in result.tags.itertuples():
        pings = int((heard[row.tag] > 0).sum())  # the transmissions a receiver heard
        per = detections.loc[detections["transmitter"] == row.tag, "serial"].value_counts()
        listed = [f"{s}: {n:,}" for s, n in per.items()]
        assert row.status == "refused" and row.receivers == len(per) and row.detections == per.sum()
        if row.tag.endswith("2000"):  # across the line at one place: two receivers heard it, ever
            assert len(per) == 2 and row.reason_code == "too_few_receivers" and row.pings == pings
            assert row.reason in (f"heard by 2 receivers (detections {', '.join(order)}): positioning needs 3 at once"
                                  for order in (listed, listed[::-1]))
            continue
        assert len(per) == 4 and row.reason_code == "too_few_receivers_at_once"
        assert row.pings == pings and row.pings_at_once == 0 and row.not_positioned == pings
        assert row.reason.startswith(f"0 of {pings:,} pings heard by 3 receivers or more at once (never more than 2 "
                                     f"at once; heard by {len(per)} receivers, detections ")
        assert set(row.reason.split(" detections ")[1].split("): ")[0].split(", ")) == set(listed)
        assert row.reason.endswith("positioning needs 3 at once, and a track at least 3 such pings")


@pytest.mark.slow
def test_whole_second_times_on_clocks_nobody_synchronised(tmp_path):
    """A simulated study's detections rounded down to whole seconds, no sync tag: every tag refused for its times,
    1 s being 1,480 m of range, against the sound's crossing time of the receivers that hear one of its pings (the
    median over its emissions heard by 3 receivers or more of their receivers' extent, computed here from the
    simulated emissions and positions); the same detections to the microsecond pass that check (the tag
    tracked)."""
    sim = simulate_study(n_receivers=9, n_tags=3, days=0.1, redeployed=0, seed=6, offset=0.0, drift=0.0)
    files, d = _without_sync(sim, tmp_path / "whole", np.floor)
    result = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], workers=1)
    check_tag_rows(result.tags, result.tracks, _given(files))
    where = dict(zip(sim.deployments["ins_serial_no"], sim.positions))
    for row in result.tags.itertuples():
        mine = d[d["transmitter"] == row.tag]
        emitted = sim.truth[row.tag]["tau"].to_numpy() + sim.origin
        ping = np.abs(mine["time"].to_numpy()[:, None] - emitted[None]).argmin(axis=1)  # its emission (100 s apart)
        extents = []
        for _, serials in mine.groupby(ping)["serial"]:
            if serials.nunique() >= 3:
                p = np.array([where[s] for s in serials])
                extents.append(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
        crossing = 1000 * np.median(extents) / SPEED
        assert row.status == "refused" and row.reason_code == "whole_seconds_unsynchronised"
        assert row.time_resolution_s == 1.0 and row.pings_at_once >= 3
        assert row.reason.startswith("whole-second, unsynchronised times: 1 s is 1,480 m of range at 1,480 m/s "
                                     "(the rounding alone 0.29 s, 427 m, one standard deviation), where sound crosses "
                                     "the receivers that hear one of its pings at once in ")
        said = float(row.reason.split(" at once in ")[1].split(" ms")[0].replace(",", ""))
        assert abs(said - crossing) <= 0.02 * crossing + 1, (said, crossing)
    fine, _ = _without_sync(sim, tmp_path / "fine")
    tag = sim.sheet["transmitter"].iloc[0]
    tracked = sblsim.track(fine["detections"], receivers=fine["deployments"], tags=fine["tags"], tag=tag, workers=1)
    check_tag_rows(tracked.tags, tracked.tracks, _given(fine))
    assert tracked.tags["status"].tolist() == ["tracked"] and tracked.tags["time_resolution_s"].iloc[0] < 1.0


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    """A simulated study with no sync tag (clocks synchronised already), read as a study reads it: the rbi tag's
    detections, the receivers table and the clocks taken as logged."""
    from sblsim.orchestrator.readers.assign import assign
    from sblsim.orchestrator.readers.deployments import read_deployments
    from sblsim.orchestrator.readers.detections import read_detections
    from sblsim.orchestrator.sync.clocks import logged_clocks

    sim = simulate_study(n_receivers=9, n_tags=3, days=0.1, redeployed=0, seed=8, offset=0.0, drift=0.0)
    files, d = _without_sync(sim, tmp_path_factory.mktemp("logged"))
    assigned = assign(read_detections(files["detections"], None), read_deployments(files["deployments"]))
    times = assigned.detections.frame["time"].to_numpy(float)
    clocks = logged_clocks(assigned.hydrophones["receiver"].tolist(), np.floor(times.min()), np.ceil(times.max()))
    rbi = sim.sheet.loc[sim.sheet["ping_type"] == "rbi", "transmitter"].iloc[0]
    return assigned, clocks, rbi, d


def test_stray_codes_heard_alone_do_not_contradict_a_sheet_s_interval(logged):
    """The rbi tag (100 to 200 s) with a receiver logging its code every 25 to 40 s besides (stray decodes, each
    heard by that receiver alone: steps far below 100 s): its sheet's interval stands, judged on the pings heard by
    3 receivers at once, whose steps are the tag's own; the same sheet stating 300 to 600 s is refused with the
    steps those pings show, naming the tag sheet and --force-interval (``sblsim track``'s)."""
    from sblsim.orchestrator.sync.toa import build_toa
    from sblsim.orchestrator.telemetry.census import TRACK_OPTIONS

    assigned, clocks, rbi, _ = logged
    frame = assigned.detections.frame
    mine = frame[frame["tag"] == rbi]
    victim = mine["receiver"].value_counts().index[0]
    rng = np.random.default_rng(2)
    at = mine["time"].min() + np.cumsum(rng.uniform(25, 40, int(np.ptp(mine["time"]) / 32)))
    at = at[at < mine["time"].max()]
    strays = pd.DataFrame({c: mine[c].iloc[0] for c in mine.columns}, index=range(len(at))).assign(
        receiver=victim, time=at)
    noisy = pd.concat([mine, strays]).sort_values("time", kind="stable").reset_index(drop=True)
    data = replace(assigned.detections, frame=noisy)
    steps = np.diff(np.sort(noisy.loc[noisy["receiver"] == victim, "time"].to_numpy()))
    assert (steps < 100).mean() > 0.5  # at one receiver the stated interval is contradicted by most steps
    kind = {"type": "rbi", "burst_interval_s": [100, 200]}
    matrix = build_toa(data, assigned.hydrophones, clocks, rbi, 100.0, kind, False, TRACK_OPTIONS)
    seen = matrix.summary["interval_seen"]
    assert not seen["contradicted"] and seen["below"] <= 0.1 * seen["steps"]
    with pytest.raises(ModelError) as refused:
        build_toa(data, assigned.hydrophones, clocks, rbi, 300.0, kind | {"burst_interval_s": [300, 600]}, False,
                  TRACK_OPTIONS)
    said = str(refused.value)
    assert said.startswith("burst interval: 300:600 s stated, but the detections' steps at one receiver show ")
    low = float(said.split(" show ")[1].split("-")[0])
    assert 95 <= low <= 200  # the tag's own steps, not the strays' 25-40 s
    assert "--ping-type" not in said and "(--tags)" in said and "--force-interval to use it anyway" in said


def test_an_interval_too_few_steps_show_names_the_tag_sheet(tmp_path):
    """Without a tag sheet, a tag whose few pings (a 9-minute study) show too few steps to infer its interval is
    refused naming how ``sblsim track`` takes one (the tag sheet), with its pings counted."""
    sim = simulate_study(n_receivers=5, n_tags=2, days=0.006, redeployed=0, seed=1, offset=0.0, drift=0.0)
    files, d = _without_sync(sim, tmp_path)
    result = sblsim.track(files["detections"], receivers=files["deployments"], workers=1)
    check_tag_rows(result.tags, result.tracks, [files["detections"], files["deployments"]])
    for row in result.tags.itertuples():
        assert row.status == "refused", row
        assert row.reason_code == "interval_unknown" and row.pings_at_once >= 3
        assert "--ping-type" not in row.reason and "the tag sheet's ping_type" in row.reason


def test_whole_second_times_the_sync_tags_cannot_synchronise(tmp_path):
    """The same study rounded to whole seconds WITH its sync tags: the synchronisation refuses the times (the rounding
    named), the study goes on with the clocks as logged (said) and every animal is a row whose reason is the
    rounding, not a count of pings that clocks seconds apart split: exit 0, nothing positioned."""
    sim = simulate_study(n_receivers=9, n_tags=3, days=0.1, redeployed=0, seed=6)
    files = sim.write(tmp_path / "files", "vue")
    d = sim.detections.assign(time=np.floor(sim.detections["time"].to_numpy()))
    files["detections"].write_text(vue_text(d))
    result = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], workers=1)
    check_tag_rows(result.tags, result.tracks, _given(files))
    assert result.summary["clocks"]["source"] == "as logged (times too coarse to synchronise)"
    assert any("cannot be synchronised" in n and "whole seconds" in n for n in result.summary["notes"])
    assert len(result.tracks) == 0 and (result.tags["reason_code"] == "whole_seconds_unsynchronised").all()
    assert all("the sync tags could not set the clocks" in r and "sync tags (transmitter" not in r
               for r in result.tags["reason"])
