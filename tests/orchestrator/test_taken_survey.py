"""The survey error a synchronisation's folder says it took (orchestrator/sync/taken_survey.py): the number where
``sync.json`` says it was seen and taken, none where stated or absent; on refined positions each receiver's own
(``positions.csv``'s ``position_sigma_m``); and the files read as
anyone's (one-line refusals of what is not the file sblsim sync writes; a link out of the folder not followed)."""

from __future__ import annotations

import json

import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.sync.taken_survey import folder_position_sigmas, folder_survey, position_errors


def _folder(tmp_path, content):
    folder = tmp_path / "sync"
    folder.mkdir()
    if content is not None:
        text = content if isinstance(content, str) else json.dumps(content, indent=2)
        (folder / "sync.json").write_text(text)
    return folder


@pytest.mark.parametrize("content,expected", [
    ({"survey_sigma_m": 2.39, "survey_sigma_from": "seen", "survey_error": {"seen": True}}, 2.39),
    ({"survey_sigma_m": 0, "survey_sigma_from": "seen"}, 0.0),
    ({"survey_sigma_m": 1.0, "survey_sigma_from": "stated"}, None),  # stated: the user's, not taken again
    ({"survey_error": {"seen": False}}, None),
    (None, None),  # a folder without sync.json (clocks written by hand): nothing seen
])
def test_the_error_taken_where_the_synchronisation_took_it(tmp_path, content, expected):
    assert folder_survey(_folder(tmp_path, content)) == expected


@pytest.mark.parametrize("content,message", [
    ("{not json", "is not JSON"),
    ("[1, 2]", "holds no JSON object"),
    ("[" * 100_000 + "]" * 100_000, "is not JSON"),  # nested past the parser's recursion
    ({"survey_sigma_m": "2.39", "survey_sigma_from": "seen"}, "survey_sigma_m: '2.39' is not a number"),
    ({"survey_sigma_m": -1.0, "survey_sigma_from": "seen"}, "survey_sigma_m: -1.0 is outside the allowed range"),
    ({"survey_sigma_m": 1e9, "survey_sigma_from": "seen"}, "is outside the allowed range [0, 1000] m"),
    ({"survey_sigma_m": None, "survey_sigma_from": "seen"}, "survey_sigma_m: None is not a number"),
])
def test_a_file_that_is_not_sblsim_syncs_is_refused_in_one_line(tmp_path, content, message):
    with pytest.raises(ModelError, match=None) as caught:
        folder_survey(_folder(tmp_path, content))
    said = str(caught.value)
    assert message in said and "\n" not in said, said


def test_a_link_out_of_the_folder_is_not_followed(tmp_path):
    outside = tmp_path / "elsewhere.json"
    outside.write_text(json.dumps({"survey_sigma_m": 2.0, "survey_sigma_from": "seen"}))
    folder = _folder(tmp_path, None)
    (folder / "sync.json").symlink_to(outside)
    with pytest.raises(ModelError) as caught:
        folder_survey(folder)
    assert "sync.json" in str(caught.value) and "\n" not in str(caught.value)



def _refined(tmp_path, rows=None):
    """A refined synchronisation's folder: ``positions.csv`` as sblsim sync writes it (every column; the sigmas
    empty where not refined)."""
    folder = _folder(tmp_path, {"positions": {"refined": True, "survey_sigma_m": 3.0}})
    rows = rows or [("A", "True", "0.3"), ("B", "False", "3"), ("C", "True", "0.75")]
    lines = ["serial,x_m,y_m,sigma_x_m,refined,reason,sigma_ratio,position_sigma_m"]
    lines += [f"{n},{k},0,{'0.3' if f == 'True' else ''},{f},,0.5,{v}" for k, (n, f, v) in enumerate(rows)]
    (folder / "positions.csv").write_text("\n".join(lines) + "\n")
    return folder


def test_refined_positions_carry_each_ones_error(tmp_path):
    """Each listed receiver's ``position_sigma_m``; one the folder does not list takes the largest listed (the
    survey's, where any position was left as surveyed)."""
    got = folder_position_sigmas(_refined(tmp_path), ["A", "B", "C", "E"])
    assert got == pytest.approx({"A": 0.3, "B": 3.0, "C": 0.75, "E": 3.0})


def test_each_positions_error_is_its_shape_sigma_or_the_surveys():
    assert position_errors(["A", "B", "C"], [0.1, 0.6, 0.25], [True, False, True], 3.0) == pytest.approx(
        {"A": 0.3, "B": 3.0, "C": 0.75})


def test_positions_not_refined_carry_none(tmp_path):
    """No positions.csv, or one written before its position_sigma_m column: None (no error known)."""
    assert folder_position_sigmas(_folder(tmp_path, {"survey_sigma_m": 2.0, "survey_sigma_from": "seen"}),
                                  ["A"]) is None
    (tmp_path / "older").mkdir()
    older = _folder(tmp_path / "older", {"positions": {"survey_sigma_m": 3.0}})
    (older / "positions.csv").write_text("serial,x_m,y_m,refined,sigma_ratio\nA,0,0,True,0.1\n")
    assert folder_position_sigmas(older, ["A"]) is None


@pytest.mark.parametrize("rows,message", [
    ([("A", "True", "abc")], "column position_sigma_m: 'abc' is not allowed"),
    ([("A", "True", "-1")], "column position_sigma_m: '-1' is not allowed"),
    ([("A", "True", "1e9")], "column position_sigma_m: '1e9' is not allowed"),
    ([("A", "True", "")], "column position_sigma_m: '' is not allowed"),
    ([("A", "True", "0.1"), ("A", "True", "0.2")], "a receiver is listed twice"),
    ([("../A", "True", "0.1")], "column serial: '../A' is not allowed"),
])
def test_refined_positions_refused_in_one_line(tmp_path, rows, message):
    with pytest.raises(ModelError) as caught:
        folder_position_sigmas(_refined(tmp_path, rows=rows), ["A"])
    said = str(caught.value)
    assert message in said and "\n" not in said, said
