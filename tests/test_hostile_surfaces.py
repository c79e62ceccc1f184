"""The hostile corpus of the surfaces issue 42 names: calibrate and its readers, the site's casts and depths,
and the lock of an output folder, each given what a careless or hostile user gives, as a user runs it (a
subprocess, as root in the project's CI).

Each case must end with exit status 2, no traceback, one line ``sblsim: error: ...`` naming the field and what
is allowed, and its folder unchanged byte for byte (nothing written, no temporary folder left); the lock's
case also that nothing was created where its link points. The cases run two at a time, each in a folder of its
own. (The signals' cases are in ``tests/orchestrator/test_interrupt.py``, the API's in ``tests/test_api.py``.)
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from sblsim.models.acoustics.sound_speed import MAX_CAST_BYTES, MAX_CAST_ROWS
from sblsim.orchestrator.surveys.gnatss import ncl1_paths
from sblsim.orchestrator.surveys.gnatss_files import J2000_POSIX, read_pxp_tt

#: The GNATSS converter, as its docstring tells a user to run it.
GNATSS = [sys.executable, "-m", "sblsim.orchestrator.surveys.gnatss"]
SBLSIM = [sys.executable, "-m", "sblsim.orchestrator.cli"]
PINGS = 3  # NCL1's first pings: the GNATSS cases' survey


def _gnatss(pxp: str = "pxp_tt", pos: str = "pos") -> list[str]:
    return [*GNATSS, "--pxp-tt", pxp, "--posfilter", pos, "--site", "site.toml", "--out", "log.csv"]


#: id -> (command, text the one line must hold)
CASES = {
    # the lock file's name a dangling link (to a file outside the folder): never created through it
    "calibrate lock through a dangling link": ([*SBLSIM, "calibrate", "box-in", "--out", "o"],
                                               "--out: the lock file"),
    "run lock through a link to a file": ([*SBLSIM, "run", "semicircle", "--out", "r"], "--out: the lock file"),
    # a sound speed the replies do not determine (a circle at one radius): refused, not 1995 m/s
    "calibrate unobservable sound speed": ([*SBLSIM, "calibrate", "box-in", "--out", "o2", "--set",
                                            "solver.solve_sound_speed=true"],
                                           "solve_sound_speed: the replies of the log do not determine the sound "
                                           "speed"),
    # GNATSS readers
    "gnatss positions of another site": (_gnatss(pos="pos_far"), "line 1: the position is"),
    "gnatss indefinite covariance": (_gnatss(pos="pos_indefinite"),
                                     "line 2: the covariance (columns 5-13) is not positive definite"),
    "gnatss no reply": (_gnatss(pxp="pxp_silent"), "holds no reply"),
    # casts
    "cast depths out of order": ([*SBLSIM, "run", "semicircle", "--set", "acoustics.sound_speed_profile=unordered.csv"],
                                 "unordered.csv' line 4, column 'depth': depth 30 m is above line 3's 100 m"),
    "cast beyond the bytes": ([*SBLSIM, "run", "semicircle", "--set", "acoustics.sound_speed_profile=huge.csv"],
                              f"a cast is at most {MAX_CAST_BYTES // 2**20} MiB"),
    "cast beyond the rows": ([*SBLSIM, "run", "semicircle", "--set", "acoustics.sound_speed_profile=long.csv"],
                             f"has more than {MAX_CAST_ROWS:,} rows"),
    # depths against the site's water depth
    "map below the lbl floor": ([*SBLSIM, "map", "lbl-field", "--depth", "301", "--out", "m"],
                                "--depth: 301 m is outside the allowed range [0, 300) m"),
    "map below the usbl site's water": ([*SBLSIM, "map", "usbl-deep", "--depth", "1001", "--out", "m"],
                                        "--depth: 1001 m is outside the allowed range [0, 1000) m"),
    "map on the lbl transponders": ([*SBLSIM, "map", "lbl-field", "--depth", "299.5", "--out", "m"],
                                    "--depth: 299.5 m is not above the seafloor: platform.seafloor_depth: 299 m"),
}


def _gnatss_files() -> dict[str, bytes]:
    """NCL1's first pings (pxp_tt, their POSFILTER lines and the site), and the hostile variants."""
    pxp_path, pos_path, site_path = ncl1_paths()
    pxp_lines = pxp_path.read_text().splitlines()[:PINGS]
    last = read_pxp_tt(pxp_path, 3)["t_tx_s"].iloc[PINGS - 1] - J2000_POSIX
    pos_lines = [line for line in pos_path.read_text().splitlines() if float(line.split()[0]) <= last + 5.0]
    far = pos_lines[0].split()
    far[1] = repr(float(far[1]) + 3.0e6)  # 3,000 km of ECEF x: another site's position
    indefinite = pos_lines[1].split()
    indefinite[4:13] = ["1e-3", "5e-3", "0", "5e-3", "1e-3", "0", "0", "0", "1e-3"]  # symmetric, |rho| = 5
    silent = [" ".join(line.split()[:2] + ["0"] * (len(line.split()) - 2)) for line in pxp_lines]
    return {"pxp_tt": "\n".join(pxp_lines) + "\n", "pos": "\n".join(pos_lines) + "\n",
            "pos_far": "\n".join([" ".join(far), *pos_lines[1:]]) + "\n",
            "pos_indefinite": "\n".join([pos_lines[0], " ".join(indefinite), *pos_lines[2:]]) + "\n",
            "pxp_silent": "\n".join(silent) + "\n", "site.toml": site_path.read_text()}


def _prepare(folder: Path, gnatss: dict[str, str]) -> None:
    folder.mkdir(parents=True)
    for name, text in gnatss.items():
        (folder / name).write_text(text)
    (folder / "unordered.csv").write_text("depth,sound_speed\n0,1510\n100,1489\n30,1508\n300,1487\n")
    (folder / "long.csv").write_text("depth,sound_speed\n" + "0,1500\n" * (MAX_CAST_ROWS + 1))
    with open(folder / "huge.csv", "wb") as handle:  # sparse: its size is what is refused, before any read
        handle.write(b"depth,sound_speed\n0,1500\n")
        handle.truncate(MAX_CAST_BYTES + 2**20)
    os.symlink(folder.parent / f"{folder.name}-outside", folder / ".o.lock")
    (folder.parent / f"{folder.name}-target").write_text("a stranger's file\n")
    os.symlink(folder.parent / f"{folder.name}-target", folder / ".r.lock")


def _snapshot(folder: Path) -> dict[str, str]:
    out = {}
    for p in sorted(folder.rglob("*")):
        key = str(p.relative_to(folder))
        out[key] = (f"link:{os.readlink(p)}" if p.is_symlink() else
                    hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir")
    return out


def _run(case: str, folder: Path, gnatss: dict[str, str]):
    _prepare(folder, gnatss)
    before = _snapshot(folder)
    target = (folder.parent / f"{folder.name}-target").read_bytes()
    args, _ = CASES[case]
    proc = subprocess.run(args, cwd=folder, capture_output=True, text=True, timeout=600, check=False)
    outside = sorted(p.name for p in folder.parent.glob(f"{folder.name}-*"))
    return proc, before, _snapshot(folder), outside, target == (folder.parent / f"{folder.name}-target").read_bytes()


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    """Every case, run two at a time (each in a folder of its own)."""
    root = tmp_path_factory.mktemp("hostile")
    gnatss = _gnatss_files()
    with ThreadPoolExecutor(max_workers=2) as pool:
        futures = {case: pool.submit(_run, case, root / f"case{k:02d}", gnatss) for k, case in enumerate(CASES)}
        return {case: f.result() for case, f in futures.items()}


def test_the_gnatss_cases_differ_from_a_survey_that_converts(tmp_path):
    """The files the GNATSS cases spoil convert as they are: each case fails for its one change."""
    for name, text in _gnatss_files().items():
        (tmp_path / name).write_text(text)
    proc = subprocess.run(_gnatss(), cwd=tmp_path, capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr
    assert f"replies of {PINGS} pings written to log.csv" in proc.stdout


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_hostile_input_is_one_line_exit_2_and_changes_nothing(outcomes, case):
    proc, before, after, outside, untouched = outcomes[case]
    _, needle = CASES[case]
    assert proc.returncode == 2, (proc.returncode, proc.stdout[-500:], proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("sblsim: error:"), proc.stderr
    assert needle in lines[0], (needle, lines[0])
    assert after == before, "the folder changed"
    # nothing was created where the dangling lock link points, the file the other one points to is unchanged
    assert len(outside) == 1 and outside[0].endswith("-target") and untouched, outside


@pytest.mark.slow
def test_a_cast_within_the_limits_is_resampled(tmp_path):
    """The largest cast accepted (rows and bytes) is read and resampled, not refused."""
    from sblsim.models.acoustics.sound_speed import MAX_PROFILE_ROWS, read_cast_csv

    z = np.arange(MAX_CAST_ROWS) * 0.05
    (tmp_path / "cast.csv").write_text("depth,sound_speed\n" + "".join(f"{a:.2f},{1500 + 0.001 * a:.4f}\n" for a in z))
    assert (tmp_path / "cast.csv").stat().st_size < MAX_CAST_BYTES
    table = read_cast_csv(tmp_path / "cast.csv")
    assert table.shape == (MAX_PROFILE_ROWS, 2) and table[-1, 0] == pytest.approx(z[-1])
    np.testing.assert_allclose(table[:, 1], 1500 + 0.001 * table[:, 0], rtol=0, atol=1e-4)  # 4 decimals written
