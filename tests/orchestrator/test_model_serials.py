"""A deployments sheet whose serials carry the receiver's model (``VR2AR-461000``, as VUE and Fathom name a receiver,
whose readers keep ``461000``): taken as the serials the detections name (orchestrator/readers/assign.py
``serials_as_logged``), said in a note. Before, no detection was put at those deployments and every tag was refused
as heard by too few receivers, a false reason."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from sblsim.orchestrator import cli
from sblsim.orchestrator.readers.assign import serials_as_logged
from sblsim.orchestrator.readers.deployments import Deployments
from sblsim.orchestrator.telemetry.simulate import simulate_study


def test_a_model_prefix_is_dropped_only_where_the_detections_name_the_serial_alone():
    given = ["VR2AR-461000", "VR2W-461001", "461002", "VR2AR-461003", "VR2W-461003", "HR2-180-461004", "A-1",
             "VR2AR-461005", "VR2W-461006"]
    logged = ["461000", "461001", "461002", "461003", "461004", "A-1", "1", "461005", "VR2W-461006"]
    table = pd.DataFrame({"receiver": given, "serial": given, "x": np.arange(len(given), dtype=float)})
    out, note = serials_as_logged(Deployments(table, None, "sheet.csv", ["read"]), logged)
    # independently: a serial no detection names whole, whose text after its last dash one does, that no other
    # serial of the sheet is or becomes
    tails = [g.rsplit("-", 1)[-1] for g in given]
    expected = [t if g not in logged and t in logged and t not in given and tails.count(t) == 1 else g
                for g, t in zip(given, tails)]
    assert out.table["serial"].tolist() == expected == [
        "461000", "461001", "461002", "VR2AR-461003", "VR2W-461003", "461004", "A-1", "461005", "VR2W-461006"]
    assert out.table["receiver"].tolist() == given  # the deployments' names as the sheet gives them
    assert note == ("4 serials of sheet.csv given with the receiver's model (VR2AR-461000, ...) taken as the serials "
                    "the detections name (461000, ...)") and out.notes == ["read", note]
    assert table["serial"].tolist() == given  # the sheet read is not changed
    same, none = serials_as_logged(out, logged)
    assert same is out and none is None


def test_a_study_whose_sheet_names_receivers_with_their_model(tmp_path):
    """The simulated study's VUE export and deployments, the sheet's serials written as VUE names the receivers:
    the same tracks as with the plain serials, and the note."""
    sim = simulate_study(n_receivers=9, n_tags=1, days=0.1, redeployed=0, seed=12)
    files = sim.write(tmp_path / "plain", "vue")
    sheet = pd.read_csv(files["deployments"], dtype=str, keep_default_na=False)
    (tmp_path / "model").mkdir()
    sheet.assign(ins_serial_no="VR2AR-" + sheet["ins_serial_no"]).to_csv(tmp_path / "model" / "deployments.csv",
                                                                          index=False)
    runs = {}
    for name, receivers in (("plain", files["deployments"]), ("model", tmp_path / "model" / "deployments.csv")):
        assert cli.main(["track", str(files["detections"]), "--receivers", str(receivers), "--tags",
                         str(files["tags"]), "--out", str(tmp_path / f"{name}-study")]) == 0
        runs[name] = pd.read_csv(tmp_path / f"{name}-study" / "tracks.csv")
    assert len(runs["plain"]) > 50
    pd.testing.assert_frame_equal(runs["plain"], runs["model"])
    notes = json.loads((tmp_path / "model-study" / "study.json").read_text())["notes"]
    assert sum("given with the receiver's model (VR2AR-" in n for n in notes) == 1, notes
