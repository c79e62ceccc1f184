"""The survey error a synchronisation's folder says it took (orchestrator/sync/taken_survey.py): the number where
``sync.json`` says it was seen and taken, none where stated or absent, and the file read as anyone's (one-line
refusals of what is not the file sblsim sync writes; a link out of the folder not followed)."""

from __future__ import annotations

import json

import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.sync.taken_survey import folder_survey


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
