"""Every configuration key that names a file is declared as one (``Variable.file``), and every rule for file keys
reads that one declaration (:func:`sblsim.orchestrator.cosim.config.file_keys`).

* The walk: every free-text key of every section (the ``receiver`` section of every built-in receiver) is set to the
  path of a sentinel file (and to ``PREFIX:path`` for each ``PREFIX:PATH`` its description names), alone and with
  each choice of its section's choice keys, and the configuration is made into a run's plan under an audit hook
  (:func:`sys.addaudithook`) that records every ``open`` of a sentinel. A key whose sentinel was opened must be a
  declared file key; a declared file key must be opened by one of them (so the walk sees what it must); the keys
  whose description says they take a path or a CSV are exactly the declared ones.
* A design's ``set`` naming a private CSV in a file key (``receiver.sound_speed_profile`` included) is refused in one
  line and the file is never opened; a built-in source in the same key is not a file.
* A scenario file's relative paths in every file key are taken from the scenario's folder.
"""

from __future__ import annotations

import os
import re
import sys

import pytest

import sblsim
from sblsim.models import RECEIVER_MODELS
from sblsim.models.errors import SblsimError
from sblsim.orchestrator.cosim.config import SECTIONS, file_keys, load_config, named_files, section_variables
from sblsim.orchestrator.cosim.plan import load_plan

#: The sentinel files the hook watches (their resolved paths); the hook records an ``open`` of any of them.
_WATCHED: set[str] = set()
_OPENED: list[str] = []


def _hook(event, detail):
    if event == "open" and _WATCHED and detail and isinstance(detail[0], (str, bytes, os.PathLike)):
        name = os.path.realpath(os.fsdecode(detail[0]))
        if name in _WATCHED:
            _OPENED.append(name)


sys.addaudithook(_hook)  # one hook per process: it does nothing while no file is watched


@pytest.fixture
def watched(tmp_path):
    """Sentinel files (a CSV cast, a Python file, an "FMU"), watched by the hook while the test runs."""
    files = {"csv": tmp_path / "private.csv", "py": tmp_path / "private.py", "fmu": tmp_path / "private.fmu"}
    files["csv"].write_text("depth,sound_speed\n0,1500\n100,1490\n")
    files["py"].write_text("# no receiver here\n")
    files["fmu"].write_bytes(b"PK\x05\x06" + bytes(18))
    _WATCHED.update(os.path.realpath(p) for p in files.values())
    _OPENED.clear()
    yield files
    _WATCHED.clear()
    _OPENED.clear()


def _free_text_keys():
    """(section, key, receiver, description) of every free-text String key of every section."""
    out = {}
    for section in SECTIONS:
        for receiver in (RECEIVER_MODELS if section == "receiver" else ("ekf",)):
            for v in section_variables(section, receiver):
                if v.type == "String" and v.choices is None:
                    out.setdefault((section, v.name), (receiver, v.description))
    return out


def _opens(section, key, receiver, description, files) -> bool:
    """Whether a plan with ``section.key`` set to a sentinel (bare or behind a prefix its description names) opens
    it, alone or with one choice of a choice key of its section."""
    values = [str(files["csv"])] + [f"{prefix}:{files['py' if prefix == 'model' else prefix]}"
                                    for prefix in re.findall(r"\b([a-z]+):PATH", description)]
    choices = [[]] + [[f"{section}.{v.name}={c}"] for v in section_variables(section, receiver) if v.choices
                      for c in v.choices]
    base = [] if section == "simulation" else [f"simulation.receiver={receiver}"]
    for value in values:
        for extra in choices:
            _OPENED.clear()
            try:
                load_plan("semicircle", [*base, *extra, f"{section}.{key}={value!r}"])
            except SblsimError:
                pass  # opened, then refused (the sentinel is no receiver, no FMU), or refused first
            if _OPENED:
                return True
    return False


def test_every_key_that_opens_a_path_is_a_declared_file_key(watched):
    declared = set(file_keys())
    opened = {(section, key) for (section, key), (receiver, description) in _free_text_keys().items()
              if _opens(section, key, receiver, description, watched)}
    assert opened - declared == set(), "keys that open a path without being declared file keys"
    assert declared - opened == set(), "declared file keys the walk did not see opened: the walk is blind"
    assert {("receiver", "sound_speed_profile"), ("acoustics", "sound_speed_profile")} <= declared


def test_the_keys_whose_description_names_a_path_are_the_declared_ones():
    said = {k for k, (_, description) in _free_text_keys().items() if re.search(r"\b(path|csv)\b", description, re.I)}
    assert said == set(file_keys())


@pytest.mark.parametrize("key", ["receiver.sound_speed_profile", "acoustics.sound_speed_profile",
                                 "target.trajectory_file"])
def test_a_design_set_naming_a_private_csv_is_refused_unopened(watched, key, tmp_path):
    problem = {"name": "x", "scenario": "semicircle", "set": [f"{key}={watched['csv']}"]}
    with pytest.raises(sblsim.ConfigError) as caught:
        sblsim.design(None, design=problem, work_area={"radius_m": 30.0, "depths_m": [5.0]}, workers=1)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"design.set: {key} names a file")
    assert _OPENED == []


def test_a_builtin_source_in_a_file_key_names_no_file():
    assert named_files({"receiver": {"sound_speed_profile": "acoustics"},
                        "acoustics": {"sound_speed_profile": "ctd:NCL1"}, "simulation": {"receiver": "lsq"}}) == []
    assert named_files({"receiver": {"sound_speed_profile": "cast.csv"}}) == [
        ("receiver", "sound_speed_profile", "cast.csv")]


def test_a_scenario_files_relative_paths_are_taken_from_its_folder(tmp_path, monkeypatch):
    folder = tmp_path / "site"
    folder.mkdir()
    (folder / "cast.csv").write_text("depth,sound_speed\n0,1500\n100,1490\n")
    (folder / "s.toml").write_text('[simulation]\nreceiver = "lsq"\nduration = 1.0\n'
                                   '[receiver]\nsound_speed_profile = "cast.csv"\n'
                                   '[acoustics]\nsound_speed_profile = "cast.csv"\n')
    monkeypatch.chdir(tmp_path)
    cfg = load_config(folder / "s.toml")
    cast = str((folder / "cast.csv").resolve())
    assert cfg["receiver"]["sound_speed_profile"] == cast and cfg["acoustics"]["sound_speed_profile"] == cast


def test_a_scenario_files_path_led_out_of_its_folder_by_a_symlink_is_refused(tmp_path, monkeypatch, capsys):
    """``cast.csv`` in the scenario's folder a symbolic link to a file elsewhere: refused in one line naming the key
    and where the link leads, exit 2, the file never opened (the audit hook); a link to a file inside the folder is
    taken; the same outside file named with ``--set`` (the user named it) is taken."""
    from sblsim.orchestrator.cli import main

    folder, elsewhere = tmp_path / "site", tmp_path / "private"
    folder.mkdir()
    elsewhere.mkdir()
    secret = elsewhere / "cast.csv"
    secret.write_text("depth,sound_speed\n0,1500\n100,1490\n")
    (folder / "cast.csv").symlink_to(secret)
    (folder / "s.toml").write_text('[simulation]\nduration = 1.0\n[acoustics]\nsound_speed_profile = "cast.csv"\n')
    monkeypatch.chdir(tmp_path)
    _WATCHED.add(os.path.realpath(secret))
    _OPENED.clear()
    try:
        assert main(["run", str(folder / "s.toml"), "--out", str(tmp_path / "o")]) == 2
        assert not _OPENED, _OPENED
    finally:
        _WATCHED.clear()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "acoustics.sound_speed_profile: 'cast.csv' leads through a symbolic link" in err[0], err
    assert str(secret) in err[0] and not (tmp_path / "o").exists()
    (folder / "inside.csv").write_text(secret.read_text())
    (folder / "cast.csv").unlink()
    (folder / "cast.csv").symlink_to(folder / "inside.csv")
    assert load_config(folder / "s.toml")["acoustics"]["sound_speed_profile"] == str((folder / "inside.csv"))
    (folder / "cast.csv").unlink()
    (folder / "s.toml").write_text('[simulation]\nduration = 1.0\n')
    cfg = load_config(folder / "s.toml", [f"acoustics.sound_speed_profile={secret}"])
    assert cfg["acoustics"]["sound_speed_profile"] == str(secret)
