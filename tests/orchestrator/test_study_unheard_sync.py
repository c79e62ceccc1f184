"""A study whose deployments name sync tags its detections do not hold (orchestrator/telemetry/study_clocks.py,
orchestrator/sync/run.py ``SyncTagsUnheard``): the clocks taken as logged and said, as where no sync tag is named."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

DATA = Path(__file__).resolve().parents[2] / "data" / "boats-norway"


def test_a_study_whose_detections_hold_no_sync_tag_takes_the_clocks_as_logged(tmp_path):
    """The deployments name sync tags the detections do not hold (an OTN or GLATOS extract of a tag project holds its
    own tags alone): the study is made, its clocks taken as logged and said so (the sync tags named), each tag with
    its reason, where before it was refused whole ("fewer than two detections of the receivers table's sync tags");
    ``sblsim sync`` on the same files still refuses, in one line, exit 2."""
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
    assert study["clocks"]["source"] == UNHEARD
    said = [n for n in study["notes"] if n.startswith("none of the deployments'")]
    assert len(said) == 1 and "taken as logged" in said[0] and str(min(named)) in said[0], study["notes"]
    tags = pd.read_csv(tmp_path / "study" / "tags.csv", dtype=str, keep_default_na=False)
    assert tags["transmitter"].tolist() == ["7953"] and tags["reason"].str.len().gt(0).all()
    assert cli.main(["sync", str(tmp_path / "detections.csv"), "--receivers", str(DATA / "hydrophones.csv"),
                     "--out", str(tmp_path / "sync")]) == 2
    assert not (tmp_path / "sync").exists()
