"""A tag's folder never collides with the study's own files (issue 98 item 10): every tag's files are in
``tags/<id>/`` of the study's folder, so tags whose ids are ``tracks.csv`` and ``sync`` (legal ids of a YAPS table) are
tracked and written beside the study's ``tracks.csv`` and ``sync/``, each where it belongs."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.orchestrator.telemetry.simulate import simulate_study
from sblsim.orchestrator.telemetry.study import TAGS_FOLDER


@pytest.mark.slow
def test_tags_named_like_the_studys_files_keep_to_their_folders(tmp_path):
    sim = simulate_study(n_receivers=6, n_tags=2, days=0.1, redeployed=0, seed=4)
    sim.write(tmp_path / "files", "vue")
    names = {"A69-1602-1000": "tracks.csv", "A69-1602-1001": "sync"}
    ids = sim.detections["transmitter"].map(lambda t: names.get(t, t.rsplit("-", 1)[1]))
    whole = np.floor(sim.detections["time"].to_numpy())
    yaps = pd.DataFrame({"epo": whole.astype(np.int64), "frac": sim.detections["time"].to_numpy() - whole,
                         "tag": ids, "serial": sim.detections["serial"]})
    yaps.to_csv(tmp_path / "detections.csv", index=False, float_format="%.9f")
    deployments = sim.deployments.assign(transmitter=sim.deployments["transmitter"].str.rsplit("-", n=1).str[1])
    deployments.to_csv(tmp_path / "deployments.csv", index=False, float_format="%.10f")
    sheet = sim.sheet.assign(transmitter=[names.get(t, t.rsplit("-", 1)[1]) for t in sim.sheet["transmitter"]])
    sheet.to_csv(tmp_path / "tags.csv", index=False)
    out = tmp_path / "out"
    result = sblsim.track(tmp_path / "detections.csv", receivers=tmp_path / "deployments.csv",
                          tags=tmp_path / "tags.csv", out=out, workers=1)
    tags = result.tags.set_index("tag")
    assert set(tags.index) == {"tracks.csv", "sync"} and (tags["status"] == "tracked").all()
    assert tags.loc["tracks.csv", "folder"] == f"{TAGS_FOLDER}/tracks.csv" and tags.loc["sync", "folder"] == "tags/sync"
    assert (out / "tracks.csv").is_file() and (out / "tags" / "tracks.csv" / "track.csv").is_file()
    assert (out / "sync" / "offsets.csv").is_file() and (out / "tags" / "sync" / "track.csv").is_file()
    written = pd.read_csv(out / "tracks.csv", dtype={"tag": str})
    assert sorted(written["tag"].unique()) == ["sync", "tracks.csv"]
    for tag in ("tracks.csv", "sync"):
        own = pd.read_csv(out / "tags" / tag / "track.csv")
        assert len(own) == (written["tag"] == tag).sum()
