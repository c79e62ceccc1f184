"""No row lost (issue 96 item 6): every tag of a study is a row of ``tags.csv`` whose pings are those positioned,
set aside and not positioned (each with why), ``tracked`` only with a row positioned (:func:`tests.helpers.
check_tag_rows`, which every test that runs a study calls); the console's figures counts, never a ``nan``, no time
span without its end; a tag's matrix has a column per receiver that heard it, not per deployment of the sheet (a
network's thousand deployments made a line the tracker's reader refused, quoting a staging folder's path)."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from sblsim.models.tracking.strays import SET_ASIDE_REASON
from sblsim.orchestrator.telemetry.simulate import SYNC_SPACE, simulate_study, vue_text
from sblsim.orchestrator.telemetry.study import run_study
from tests.helpers import check_tag_rows


@pytest.fixture(scope="module")
def forced(tmp_path_factory):
    """A small simulated study whose sheet states the rbi tag's 100-200 s as 300-600 s, run by ``sblsim track``
    with --force-interval: the interval taken, its rows set aside."""
    from sblsim.orchestrator.cli import main

    folder = tmp_path_factory.mktemp("forced")
    sim = simulate_study(n_receivers=9, n_tags=3, days=0.1, redeployed=0, seed=12)
    files = sim.write(folder / "in", "vue")
    sheet = sim.sheet.copy()
    rbi = sheet.index[(sheet["ping_type"] == "rbi") & (sheet["role"] == "animal")][0]
    sheet.loc[rbi, ["min_delay", "max_delay"]] = ["300", "600"]
    sheet.to_csv(files["tags"], index=False)
    return sim, files, main, folder, sheet.loc[rbi, "transmitter"]


@pytest.mark.slow
def test_every_ping_is_counted_once_and_the_console_says_counts(forced, capsys):
    sim, files, main, folder, rbi = forced
    code = main(["track", str(files["detections"]), "--receivers", str(files["deployments"]), "--tags",
                 str(files["tags"]), "--out", str(folder / "out"), "--workers", "1", "--force-interval", "--tag", rbi])
    captured = capsys.readouterr()
    assert code == 0
    tags = pd.read_csv(folder / "out" / "tags.csv", dtype={"tag": str, "reason": str, "reason_code": str,
                                                           "not_positioned_why": str}, keep_default_na=False,
                       na_values=[""])
    tracks = pd.read_csv(folder / "out" / "tracks.csv", dtype={"tag": str, "quality_reason": str})
    check_tag_rows(tags, tracks, [str(p) for p in files.values()])
    row = tags.set_index("tag").loc[rbi]
    # the stated 300 s set aside the pings closer than it to a kept one: every one of them counted, none lost
    assert row["status"] == "tracked" and row["set_aside"] > 0
    own = pd.read_csv(folder / "out" / row["folder"] / "pings.csv")
    assert row["pings"] == len(own)  # the matrix's every ping, from the tag's own pings.csv
    aside = pd.read_csv(folder / "out" / row["folder"] / "set_aside.csv")
    assert row["set_aside"] == len(aside)
    # the console: counts as counts, no nan, a time span only with both its ends
    lines = (captured.out + captured.err).splitlines()
    assert not [line for line in lines if re.search(r"\bnan\b", line)]
    assert not [line for line in lines if re.search(r"\d\.0 (pings|positioned|rows|tags)\b", line)]
    assert not [line for line in lines if re.search(r" to ,| to $", line)]
    said = [line for line in lines if line.startswith(f"  {rbi}:")]
    assert len(said) == 1 and f"{int(row['pings']):,} pings, {int(row['positioned']):,} positioned" in said[0]
    assert f"{int(row['set_aside']):,} set aside" in said[0]
    assert len(tags) == 1 and any(line.startswith("  1 of 1 tag tracked, ") for line in lines)


def _outcome(pings: int, placed: list[int], aside: list[int], nan: list[int] = ()):
    """A track's outcome as :func:`tracked_row` reads it: the robust track's rows at ``placed`` (positioned), ``aside``
    (set aside: no estimate) and ``nan`` (a row with no position), of ``pings`` pings."""
    ping = np.array(sorted([*placed, *aside, *nan]), int)
    x = np.where(np.isin(ping, placed), 1.0, np.nan)
    rows = pd.DataFrame({"estimator": "robust", "ping": ping, "x": x, "y": x, "sigma_x": 0.5, "sigma_y": 0.5,
                         "epoch_s": 1.7e9 + ping * 100.0, "quality": np.where(np.isin(ping, aside), "flagged", "ok"),
                         "quality_reason": np.where(np.isin(ping, aside), SET_ASIDE_REASON, "")})
    summary = {"track": "robust", "pings": pings, "dimensions": 2, "flagged": {"robust": len(aside)},
               "set_aside": {"count": len(aside)}, "ping_type": {"type": "rbi"}, "wall_time_s": 1.0,
               "sound_speed": {"sound_speed_m_s": 1480.0, "source": "given"}}
    return SimpleNamespace(summary=summary, track=rows.drop(columns=["estimator", "ping"]), estimates=rows)


@pytest.mark.parametrize("pings, placed, aside, nan, before", [
    (10, [3, 4, 5, 8], [6], [], 3),  # the track starts at ping 3: pings 0-2 before it, 7 and 9 with no estimate
    (6, [0, 1, 2, 3, 4, 5], [], [], 0),
    (5, [1, 2], [], [3], 1),  # a row of the track without a position is not a position
])
def test_the_pings_a_track_does_not_position_are_counted_by_why(pings, placed, aside, nan, before):
    from sblsim.orchestrator.telemetry.tag_rows import tracked_row

    got = tracked_row(_outcome(pings, placed, aside, nan), 1.0, {"pings": pings, "pings_at_once": pings})
    missing = pings - len(placed) - len(aside)
    assert got["status"] == "tracked"
    assert (got["pings"], got["positioned"], got["set_aside"], got["not_positioned"]) == (pings, len(placed),
                                                                                           len(aside), missing)
    expected = "; ".join(f"{k} {v}" for k, v in (("before_track_start", before),
                                                  ("no_estimate", missing - before)) if v)
    assert got["not_positioned_why"] == expected


def test_a_track_with_no_row_positioned_is_no_track():
    """The tracker's outcome with every row set aside (as --force-interval can make it): refused, each ping counted,
    the reason saying the tracker positioned none of them."""
    from sblsim.orchestrator.telemetry.tag_rows import tracked_row

    got = tracked_row(_outcome(7, [], [1, 4]), 1.0, {"pings": 7, "pings_at_once": 5})
    assert got["status"] == "refused" and got["reason_code"] == "no_position"
    assert (got["pings"], got["positioned"], got["set_aside"], got["not_positioned"]) == (7, 0, 2, 5)
    assert got["not_positioned_why"] == "no_position 5"
    assert got["reason"].startswith("the tracker positioned none of its 7 pings (2 set aside as no pings of the "
                                    "stated interval; 5 heard by 3 receivers or more at once)")


@pytest.mark.slow
def test_a_network_s_thousand_deployments_make_no_thousand_columns(tmp_path):
    """A 9-receiver study in a network of 1,100 more deployments within 4 km, each of which logged another tag once:
    the tag's matrix has the columns of the receivers that heard it, and it is tracked (its line was 1,110 cells,
    over the tracker reader's 1,001)."""
    sim = simulate_study(n_receivers=9, n_tags=3, days=0.1, redeployed=0, seed=9, offset=0.0, drift=0.0)
    files = sim.write(tmp_path, "vue")
    rng = np.random.default_rng(3)
    n = 1100
    lat = sim.deployments["deploy_lat"].mean() + rng.uniform(-0.02, 0.02, n)
    lon = sim.deployments["deploy_long"].mean() + rng.uniform(-0.03, 0.03, n)
    extra = pd.DataFrame({"station": [f"N{k}" for k in range(n)], "ins_serial_no": [str(900000 + k) for k in range(n)],
                          "deploy_lat": lat, "deploy_long": lon,
                          "deploy_date_time": sim.deployments["deploy_date_time"].iloc[0],
                          "recover_date_time": sim.deployments["recover_date_time"].iloc[0], "transmitter": ""})
    pd.concat([sim.deployments.assign(transmitter=""), extra]).to_csv(files["deployments"], index=False,
                                                                       float_format="%.10f")
    d = sim.detections[~sim.detections["transmitter"].str.startswith(SYNC_SPACE)]
    other = pd.DataFrame({"serial": extra["ins_serial_no"], "model": "VR2W", "transmitter": "A69-1602-9999",
                          "time": d["time"].min() + rng.uniform(0, 3600, n)})
    files["detections"].write_text(vue_text(pd.concat([d, other]).sort_values("time").reset_index(drop=True)))
    tag = sim.sheet["transmitter"].iloc[0]
    (tmp_path / "work").mkdir()
    result = run_study(files["detections"], files["deployments"], files["tags"], workdir=tmp_path / "work",
                       chosen=[tag], workers=1)
    check_tag_rows(result.tags, result.tracks, [str(p) for p in files.values()])
    row = result.tags.iloc[0]
    assert row["status"] == "tracked", row["reason"]
    heard = sorted(d.loc[d["transmitter"] == tag, "serial"].unique())
    written = pd.read_csv(tmp_path / "work" / row["folder"] / "receivers.csv", dtype={"name": str})
    assert row["receivers"] == len(heard) and sorted(written["name"]) == heard
    assert result.matrices[row["folder"]].toa.shape[1] == len(heard)


def test_the_console_names_the_refused_tags_with_most_detections_and_counts_the_others(tmp_path):
    """12 refused tags: the 10 with the most detections named with their reasons, the other 2 counted by code; the
    last line counts the tags by code and says no rows where none was tracked."""
    from sblsim.orchestrator.telemetry.study import TAG_COLUMNS
    from sblsim.orchestrator.telemetry.study_report import MAX_REFUSED_LINES, closing_line, tag_lines

    detections = [5, 900, 3, 70, 1, 44, 8, 2, 61, 13, 400, 6]
    codes = ["one_receiver"] * 7 + ["never_detected"] * 5
    table = pd.DataFrame([{c: None for c in TAG_COLUMNS} | {
        "tag": f"T{k}", "transmitter": f"T{k}", "status": "refused", "reason_code": code, "reason": f"why {k}",
        "detections": n, "pings": n, "positioned": 0, "set_aside": 0, "not_positioned": n, "flagged": 0}
        for k, (n, code) in enumerate(zip(detections, codes))], columns=list(TAG_COLUMNS))
    lines = tag_lines(table)
    assert all(warning for _, warning in lines) and len(lines) == MAX_REFUSED_LINES + 1
    named = [line.split("tag ")[1].split(" ")[0] for line, _ in lines[:-1]]
    order = sorted(range(12), key=lambda k: -detections[k])
    assert named == [f"T{k}" for k in order[:MAX_REFUSED_LINES]]
    rest = pd.Series([codes[k] for k in order[MAX_REFUSED_LINES:]]).value_counts()
    assert lines[-1][0].startswith(f"sblsim: warning: 2 more tags not tracked ("
                                   f"{', '.join(f'{c} {n}' for c, n in rest.items())})")
    last = closing_line(table, 1.0, tmp_path, "tags.csv")
    assert last.startswith("  0 of 12 tags tracked (not tracked: one_receiver 7, never_detected 5), in 1.0 s")
