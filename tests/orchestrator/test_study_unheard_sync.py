"""A study whose deployments name sync tags its detections do not hold (orchestrator/telemetry/study_clocks.py,
orchestrator/sync/run.py ``SyncTagsUnheard``): the clocks taken as logged and said, as where no sync tag is named."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

DATA = Path(__file__).resolve().parents[2] / "data" / "boats-norway"


def test_a_study_whose_detections_hold_no_sync_tag_takes_the_clocks_as_logged(tmp_path):
    """The deployments name sync tags the detections do not hold (an OTN or GLATOS extract of a tag project holds its
    own tags alone): the study is made, its clocks taken as logged and said so (the sync tags named), each tag with
    its reason or its track, where before it was refused whole ("fewer than two detections of the receivers table's
    sync tags"); ``sblsim sync`` on the same files still refuses, in one line, exit 2."""
    import json

    from sblsim.orchestrator import cli
    from sblsim.orchestrator.telemetry.study_clocks import UNHEARD

    table = pd.read_csv(DATA / "detections.csv")
    named = set(pd.read_csv(DATA / "deployments.csv")["transmitter"].dropna().astype(int))
    table[~table["tag"].isin(named)].to_csv(tmp_path / "detections.csv", index=False)
    args = [str(tmp_path / "detections.csv"), "--receivers", str(DATA / "deployments.csv")]
    assert cli.main(["track", *args, "--tags", str(DATA / "tags.csv"), "--tag", "7953", "--out",
                     str(tmp_path / "study")]) == 0
    study = json.loads((tmp_path / "study" / "study.json").read_text())
    # (the lobster's pings then fit the clocks, or leave them as logged: test_study_clock_fit.py)
    assert study["clocks"]["source"] == UNHEARD or study["clocks"]["as_logged"]["source"] == UNHEARD
    said = [n for n in study["notes"] if n.startswith("the clocks are taken as logged")]
    assert len(said) == 1 and "fewer than two detections of the receivers table's sync tags" in said[0], said
    assert str(min(named)) in said[0], said
    tags = pd.read_csv(tmp_path / "study" / "tags.csv", dtype=str, keep_default_na=False)
    # (refused with its reason on the clocks as logged, or tracked on clocks its pings fitted: the lobster's pings
    # alone tie 7 of the 20 clocks once its sparse hours share their knots, most of its rows flagged)
    assert tags["transmitter"].tolist() == ["7953"]
    assert ((tags["status"] == "tracked") | tags["reason"].str.len().gt(0)).all(), tags.T
    assert cli.main(["sync", str(tmp_path / "detections.csv"), "--receivers", str(DATA / "hydrophones.csv"),
                     "--out", str(tmp_path / "sync")]) == 2
    assert not (tmp_path / "sync").exists()


def _boats_sync_tags():
    table = pd.read_csv(DATA / "detections.csv")
    sheet = pd.read_csv(DATA / "deployments.csv").dropna(subset=["transmitter"])
    home = dict(zip(sheet["transmitter"].astype(int), sheet["ins_serial_no"].astype(int)))
    return table, home


def test_sync_tags_each_heard_at_its_own_receiver_alone(tmp_path):
    """Every sync tag heard by its own receiver alone (no two receivers share an emission): ``sblsim sync`` refuses
    in one line saying so (before: 'reference: receiver 1623 shares fewer than 2 sync-tag emissions', the receiver
    it had chosen), and a study takes the clocks as logged, said with that reason."""
    import json

    from sblsim.orchestrator import cli

    table, home = _boats_sync_tags()
    alone = table[~table["tag"].isin(list(home)) | (table["serial"] == table["tag"].map(home))]
    alone.to_csv(tmp_path / "detections.csv", index=False)
    assert cli.main(["sync", str(tmp_path / "detections.csv"), "--receivers", str(DATA / "hydrophones.csv"),
                     "--out", str(tmp_path / "sync")]) == 2
    assert not (tmp_path / "sync").exists()
    assert cli.main(["track", str(tmp_path / "detections.csv"), "--receivers", str(DATA / "deployments.csv"),
                     "--tags", str(DATA / "tags.csv"), "--tag", "7953", "--out", str(tmp_path / "study")]) == 0
    study = json.loads((tmp_path / "study" / "study.json").read_text())
    said = [n for n in study["notes"] if n.startswith("the clocks are taken as logged")]
    assert len(said) == 1 and "no two receivers share 2 emissions of a sync tag" in said[0], study["notes"]

