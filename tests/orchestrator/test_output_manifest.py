"""An output folder never has a file replaced that sblsim did not write (orchestrator/io/manifest.py,
orchestrator/io/output.py): a user's input in ``--out``, another program's file, a result edited since; an earlier
run's own outputs are replaced (with ``--force`` where the command asks for it)."""

from __future__ import annotations

import os

import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.manifest import MANIFEST, foreign, recorded, refuse_foreign
from sblsim.orchestrator.io.output import check_output, staged_directory


def _write(out, files):
    with staged_directory(out) as tmp:
        for name, text in files.items():
            (tmp / name).write_text(text)


def test_a_staged_write_records_what_it_wrote_and_replaces_only_that(tmp_path):
    out = tmp_path / "study"
    _write(out, {"tags.csv": "a", "study.json": "{}"})
    assert set(recorded(out)) == {"tags.csv", "study.json"}
    assert foreign(out, ["tags.csv", "study.json", "absent.csv"]) == []
    _write(out, {"tags.csv": "b"})  # an earlier run's own output: replaced
    assert (out / "tags.csv").read_text() == "b" and (out / "study.json").read_text() == "{}"
    assert set(recorded(out)) == {"tags.csv", "study.json"}


def test_a_users_file_in_the_output_folder_is_never_replaced(tmp_path):
    """The issue's case: ``--out in`` where ``in/`` holds the study's inputs: the write is refused whole, the user's
    files unchanged, nothing of the run left."""
    out = tmp_path / "in"
    out.mkdir()
    (out / "tags.csv").write_text("transmitter\n4555\n")
    (out / "detections.csv").write_text("mine")
    with pytest.raises(ModelError) as refused:
        _write(out, {"tags.csv": "the study's", "tracks.csv": "rows"})
    line = str(refused.value)
    assert "\n" not in line and "tags.csv" in line and "did not write" in line
    assert (out / "tags.csv").read_text() == "transmitter\n4555\n"
    assert sorted(p.name for p in out.iterdir()) == ["detections.csv", "tags.csv"]  # no tracks.csv, no staging
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]


def test_a_result_edited_since_is_the_users(tmp_path):
    out = tmp_path / "r"
    _write(out, {"tags.csv": "a"})
    path = out / "tags.csv"
    path.write_text("edited by hand")
    os.utime(path, ns=(path.stat().st_atime_ns, path.stat().st_mtime_ns + 10**9))
    assert foreign(out, ["tags.csv"]) == ["tags.csv"]
    with pytest.raises(ModelError, match="tags.csv"):
        _write(out, {"tags.csv": "b"})
    assert path.read_text() == "edited by hand"


def test_a_manifest_that_cannot_be_read_vouches_for_nothing(tmp_path):
    out = tmp_path / "r"
    _write(out, {"summary.json": "{}"})
    for text in ("not json", '{"written": ["summary.json"]}', "[]", '{"written": {"summary.json": 3}}'):
        (out / MANIFEST).write_text(text)
        assert recorded(out) == {} or "summary.json" not in recorded(out)
        assert foreign(out, ["summary.json"]) == ["summary.json"]
    (out / MANIFEST).write_text(" " * (5 * 2**20))  # too large: not read
    assert recorded(out) == {}


def test_a_folder_is_its_own_kind(tmp_path):
    """A tag's folder written by sblsim is its own; a file of that name where a folder was is not."""
    out = tmp_path / "r"
    with staged_directory(out) as tmp:
        (tmp / "4555").mkdir()
        (tmp / "4555" / "track.csv").write_text("x")
    assert recorded(out)["4555"] == {"kind": "folder"} and foreign(out, ["4555"]) == []
    import shutil

    shutil.rmtree(out / "4555")
    (out / "4555").write_text("a file now")
    assert foreign(out, ["4555"]) == ["4555"]


def test_the_check_before_the_work_refuses_a_foreign_output_name_with_or_without_force(tmp_path):
    out = tmp_path / "in"
    out.mkdir()
    (out / "study.json").write_text("a user's own notes")
    for force in (False, True):
        with pytest.raises(ModelError, match="did not write"):
            check_output(out, force, "study.json", "study", "--out", writes=["tags.csv"])
    (out / "study.json").unlink()
    (out / "tags.csv").write_text("transmitter\n")
    with pytest.raises(ModelError, match="tags.csv"):
        check_output(out, True, "study.json", "study", "--out", writes=["tags.csv", "tracks.csv"])
    check_output(out, False, "study.json", "study", "--out", writes=["tracks.csv"])  # no clash: allowed
    refuse_foreign(out, ["tracks.csv"])


def test_an_earlier_result_still_needs_force(tmp_path):
    out = tmp_path / "r"
    _write(out, {"study.json": "{}"})
    with pytest.raises(ModelError, match="--force"):
        check_output(out, False, "study.json", "study")
    check_output(out, True, "study.json", "study")
