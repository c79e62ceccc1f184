"""One rule for every file a file names (:func:`sblsim.orchestrator.io.paths.inside`): taken from the naming file's
folder, refused in one line where the resolved path (absolute, ``..``, a symbolic link) leaves it, the file never
opened (an audit hook watches it) and no line of it quoted; the same file given on the command line is taken.

The cases: a design file's ``site.area.file`` and ``tag.burst_sequence``, a scenario file's file keys, a
synchronisation folder's ``offsets.csv`` and ``positions.csv`` (``sblsim toa --sync``), a tag sheet's sequence file.
"""

from __future__ import annotations

import os
import sys

import pytest

from sblsim.models.errors import ModelError
from sblsim.orchestrator.io.paths import inside

#: Resolved paths of the private files the hook watches, and the ones opened.
_WATCHED: set[str] = set()
_OPENED: list[str] = []
SECRET = "SECRET-7f3a9c"


def _hook(event, detail):
    if event == "open" and _WATCHED and detail and isinstance(detail[0], (str, bytes, os.PathLike)):
        name = os.path.realpath(os.fsdecode(detail[0]))
        if name in _WATCHED:
            _OPENED.append(name)


sys.addaudithook(_hook)


@pytest.fixture
def private(tmp_path):
    """A private folder beside the user's: an outline, a sequence and a clock table whose first line is a secret."""
    folder = tmp_path / "private"
    folder.mkdir()
    files = {name: folder / name for name in ("outline.csv", "seq.csv", "offsets.csv", "positions.csv")}
    for path in files.values():
        path.write_text(f"{SECRET},x\n1,2\n")
        _WATCHED.add(os.path.realpath(path))
    _OPENED.clear()
    yield files
    _WATCHED.clear()


def _refused(capsys, argv, key):
    from sblsim.orchestrator.cli import main

    assert main(argv) == 2
    assert not _OPENED, _OPENED
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0] and "outside" in err[0], err
    assert SECRET not in err[0]
    return err[0]


def _design(folder, area_file=None, sequence=None):
    """Lake Hald's design with its water or the tag's sequence named by a file key."""
    from importlib import resources

    text = resources.files("sblsim.orchestrator.designs").joinpath("lake-hald-array.toml").read_text()
    if area_file is not None:
        text = text.replace('polygon = "-60', f'file = {area_file!r}\n# polygon = "-60')
    if sequence is not None:
        text += f'\n[tag]\nping_type = "pbi"\nburst_sequence = {sequence!r}\n'
    path = folder / "pond.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("how", ["absolute", "dotdot", "link"])
def test_a_design_files_area_file_outside_its_folder_is_refused_unopened(tmp_path, private, capsys, how):
    user = tmp_path / "user"
    user.mkdir()
    named = {"absolute": str(private["outline.csv"]), "dotdot": "../private/outline.csv", "link": "outline.csv"}[how]
    if how == "link":
        (user / "outline.csv").symlink_to(private["outline.csv"])
    design = _design(user, area_file=named)
    message = _refused(capsys, ["design", str(design), "--out", str(tmp_path / "o")], "site.area.file")
    assert not (tmp_path / "o").exists()
    assert ("symbolic link" in message) == (how == "link")


@pytest.mark.parametrize("how", ["absolute", "dotdot"])
def test_a_design_files_burst_sequence_outside_its_folder_is_refused_unopened(tmp_path, private, capsys, how):
    user = tmp_path / "user"
    user.mkdir()
    named = str(private["seq.csv"]) if how == "absolute" else "../private/seq.csv"
    design = _design(user, sequence=named)
    _refused(capsys, ["design", str(design), "--out", str(tmp_path / "o")], "tag.burst_sequence")


def test_a_scenario_files_absolute_path_is_refused_and_the_same_file_on_the_command_line_taken(tmp_path, private,
                                                                                              capsys):
    from sblsim.orchestrator.cosim.config import load_config

    cast = private["outline.csv"].with_name("cast.csv")
    cast.write_text("depth,sound_speed\n0,1500\n100,1490\n")
    _WATCHED.add(os.path.realpath(cast))
    user = tmp_path / "user"
    user.mkdir()
    for named in (str(cast), "../private/cast.csv"):
        (user / "s.toml").write_text(f'[simulation]\nduration = 1.0\n[acoustics]\nsound_speed_profile = "{named}"\n')
        _refused(capsys, ["run", str(user / "s.toml"), "--out", str(tmp_path / "o")], "acoustics.sound_speed_profile")
        assert not (tmp_path / "o").exists()
    (user / "s.toml").write_text("[simulation]\nduration = 1.0\n")
    assert load_config(user / "s.toml", [f"acoustics.sound_speed_profile={cast}"])["acoustics"][
        "sound_speed_profile"] == str(cast)


@pytest.mark.parametrize("name", ["offsets.csv", "positions.csv"])
def test_a_sync_folders_table_linked_out_of_it_is_refused_unopened(tmp_path, private, name):
    from sblsim.orchestrator.sync.clocks import read_clocks, read_positions

    folder = tmp_path / "sync"
    folder.mkdir()
    (folder / name).symlink_to(private[name])
    read = read_clocks if name == "offsets.csv" else read_positions
    with pytest.raises(ModelError, match="outside the folder of the synchronisation") as error:
        read(folder)
    assert not _OPENED and SECRET not in str(error.value) and "\n" not in str(error.value)


def test_a_tag_sheets_sequence_outside_its_folder_is_refused_unopened(tmp_path, private):
    from sblsim.orchestrator.readers.tag_sheet import read_tag_sheet

    user = tmp_path / "user"
    user.mkdir()
    for named in (str(private["seq.csv"]), "../private/seq.csv"):
        (user / "tags.csv").write_text(f"transmitter,ping_type,burst_sequence\nA69-1602-5,pbi,{named}\n")
        with pytest.raises(ModelError, match="burst_sequence.*outside the folder of the tag sheet") as error:
            read_tag_sheet(user / "tags.csv")
        assert not _OPENED and SECRET not in str(error.value)


def test_the_rule_takes_what_the_folder_holds_and_nothing_else(tmp_path):
    """Within the folder by any spelling (relative, absolute, a ``..`` that comes back, a link inside): taken;
    out of it by any (absolute, ``..``, a link, a link to a link): refused; a loop of links: refused."""
    folder, other = tmp_path / "a", tmp_path / "b"
    folder.mkdir()
    other.mkdir()
    (folder / "x.csv").write_text("1\n")
    (other / "y.csv").write_text("1\n")
    (folder / "in").symlink_to(folder / "x.csv")
    (folder / "out").symlink_to(other / "y.csv")
    (folder / "hop").symlink_to(folder / "out")
    (folder / "loop1").symlink_to(folder / "loop2")
    (folder / "loop2").symlink_to(folder / "loop1")
    for text in ("x.csv", str(folder / "x.csv"), "../a/x.csv", "in"):
        assert inside(folder, text, "k", "file") == (folder / "x.csv").resolve()
    for text in (str(other / "y.csv"), "../b/y.csv", "out", "hop", "/etc/passwd", "~/.ssh/id_rsa", "loop1"):
        with pytest.raises(ModelError, match=r"^k: ") as error:
            inside(folder, text, "k", "file")
        assert "\n" not in str(error.value)


def test_a_study_files_scenario_outside_its_folder_is_refused_unopened(tmp_path, private):
    from sblsim.orchestrator.campaign.errors import StudyError
    from sblsim.orchestrator.campaign.study import load_study

    scenario = private["outline.csv"].with_name("s.toml")
    scenario.write_text("[simulation]\nduration = 1.0\n")
    _WATCHED.add(os.path.realpath(scenario))
    user = tmp_path / "user"
    user.mkdir()
    (user / "mine.toml").write_text("[simulation]\nduration = 1.0\n")
    factor = '[[factors]]\nname = "gps"\nkey = "platform.gps_sigma"\nlow = 0.1\nhigh = 3.5\n'
    for named in (str(scenario), "../private/s.toml"):
        (user / "study.toml").write_text(f'[study]\nscenarios = ["{named}"]\nreplicates = 2\n' + factor)
        with pytest.raises(StudyError, match="^study.scenarios: .*outside the folder of the study file"):
            load_study(user / "study.toml")
        assert not _OPENED
    (user / "study.toml").write_text('[study]\nscenarios = ["mine.toml", "semicircle"]\nreplicates = 2\n' + factor)
    assert load_study(user / "study.toml").scenarios[0] == str((user / "mine.toml").resolve())
