"""Archives from someone else: zip bombs, entries that climb out, symbolic links, SSP sources outside the
package. Each is refused with one line before anything is unpacked; nothing lands outside the folder."""

from __future__ import annotations

import stat
import subprocess
import sys
import zipfile

import pytest

from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.ssp import export_ssp
from sblsim.orchestrator.io import archives
from sblsim.orchestrator.io.archives import ArchiveError, inside, safe_extract


def _zip(path, entries):
    """Write ``entries``: (ZipInfo or name, bytes) pairs."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for info, data in entries:
            z.writestr(info, data)
    return path


def _link(name: str, target: str) -> tuple[zipfile.ZipInfo, bytes]:
    info = zipfile.ZipInfo(name)
    info.external_attr = (stat.S_IFLNK | 0o777) << 16
    return info, target.encode()


@pytest.mark.parametrize("entries, message", [
    ([("../evil.txt", b"x")], "climbs out"),
    ([("a/../../evil.txt", b"x")], "climbs out"),
    ([("/tmp/evil.txt", b"x")], "absolute name"),
    ([("C:/evil.txt", b"x")], "absolute name"),
    ([_link("link", "/etc")], "symbolic link"),
    ([_link("dir", "/tmp"), ("dir/evil.txt", b"x")], "symbolic link"),  # an entry "under" a symlink
    ([("zeros.bin", bytes(4 << 20))], "inflates"),  # 4 MiB of zeros deflate about 1000 times
])
def test_hostile_entries_are_refused_before_anything_is_written(tmp_path, entries, message):
    archive = _zip(tmp_path / "a.zip", entries)
    dest = tmp_path / "out"
    dest.mkdir()
    with pytest.raises(ArchiveError, match=message):
        safe_extract(archive, dest, "test.zip")
    assert list(dest.iterdir()) == []
    assert not (tmp_path / "evil.txt").exists()


def test_the_total_size_is_bounded(tmp_path, monkeypatch):
    """Many entries each below the ratio limit still may not add up to more than MAX_BYTES."""
    monkeypatch.setattr(archives, "MAX_BYTES", 3000)
    archive = _zip(tmp_path / "a.zip", [(f"f{k}", bytes(range(256)) * 4) for k in range(3)])  # 3 x 1024 B
    dest = tmp_path / "out"
    dest.mkdir()
    with pytest.raises(ArchiveError, match="more than"):
        safe_extract(archive, dest, "test.zip")
    monkeypatch.setattr(archives, "MAX_BYTES", 4000)
    safe_extract(archive, dest, "test.zip")
    assert sorted(p.name for p in dest.iterdir()) == ["f0", "f1", "f2"]
    assert (dest / "f1").read_bytes() == bytes(range(256)) * 4


def test_not_a_zip_is_one_error(tmp_path):
    (tmp_path / "a.zip").write_text("not a zip")
    with pytest.raises(ArchiveError, match="not a valid zip"):
        safe_extract(tmp_path / "a.zip", tmp_path, "test.zip")


def test_inside_refuses_paths_that_leave_the_root(tmp_path):
    assert inside(tmp_path, "resources/a.fmu") == tmp_path / "resources" / "a.fmu"
    for bad in ("../a.fmu", "/etc/passwd", "resources/../../a.fmu", "", "C:/a.fmu"):
        assert inside(tmp_path, bad) is None, bad


@pytest.fixture(scope="module")
def package(fmu_dir, tmp_path_factory):
    cfg = load_config("semicircle", ["simulation.duration=2"], seed=1)
    return export_ssp(cfg, tmp_path_factory.mktemp("ssp") / "s.ssp", fmu_dir)


def _tampered(src, dst, ssd_edit=None, extra=()):
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as b:
        for item in a.infolist():
            data = a.read(item)
            if ssd_edit and item.filename == "SystemStructure.ssd":
                data = ssd_edit(data)
            b.writestr(item, data)
        for info, data in extra:
            b.writestr(info, data)
    return dst


@pytest.mark.slow
@pytest.mark.parametrize("kind, message", [
    ("source climbs out", "is not a file inside the package"),
    ("absolute source", "is not a file inside the package"),
    ("zip bomb", "inflates"),
    ("symlink entry", "symbolic link"),
])
def test_run_of_a_hostile_ssp_is_one_line_and_writes_nothing(package, tmp_path, kind, message):
    outside = tmp_path / "elsewhere.fmu"
    outside.write_bytes((package.parent / "s.ssp").read_bytes()[:10])
    edits = {
        "source climbs out": (lambda d: d.replace(b'source="resources/sblsim_receiver.fmu"',
                                                  b'source="../elsewhere.fmu"'), ()),
        "absolute source": (lambda d: d.replace(b'source="resources/sblsim_receiver.fmu"',
                                                f'source="{outside}"'.encode()), ()),
        "zip bomb": (None, [("resources/zeros.bin", bytes(8 << 20))]),
        "symlink entry": (None, [_link("resources/link", "/etc")]),
    }
    edit, extra = edits[kind]
    ssp = _tampered(package, tmp_path / "t.ssp", edit, extra)
    with zipfile.ZipFile(ssp) as z:  # the edit really happened
        assert edit is None or z.read("SystemStructure.ssd") != zipfile.ZipFile(package).read("SystemStructure.ssd")
    work = tmp_path / "work"
    work.mkdir()
    proc = subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", "run", "--ssp", str(ssp), "--out", "r"],
                          cwd=work, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("sblsim: error:") and message in lines[0], proc.stderr
    assert list(work.iterdir()) == []
