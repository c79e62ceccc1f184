"""Swapped latitude and longitude named as the cause (issue 98 item 11): a deployments sheet whose latitudes are
under its longitude column and back is refused before the clocks are fitted, in one line saying the sync tags' travel
times fit the positions swapped (the boats' sheet swapped by hand, against the same sheet as given), by ``sblsim
track`` and ``sblsim sync`` alike."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

BOATS = Path(__file__).resolve().parents[2] / "data" / "boats-norway"


@pytest.mark.parametrize("command", [pytest.param("track", marks=pytest.mark.slow), "sync"])
def test_swapped_latitude_and_longitude_are_named(tmp_path, command):
    sheet = pd.read_csv(BOATS / "deployments.csv", dtype=str)
    sheet["deploy_lat"], sheet["deploy_long"] = sheet["deploy_long"].copy(), sheet["deploy_lat"].copy()
    sheet.to_csv(tmp_path / "swapped.csv", index=False)
    done = subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", command, str(BOATS / "detections.csv"),
                           "--receivers", str(tmp_path / "swapped.csv"), "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr[-1500:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "latitude and longitude swapped" in lines[0] and "swapped.csv" in lines[0]
    scales = [float(re.search(r"by sound ([0-9.]+) times", lines[0]).group(1)),
              float(re.search(r"not as given \(([0-9.]+) times", lines[0]).group(1))]
    assert abs(scales[0] - 1) < 0.07 and abs(scales[1] - 1) > 0.25  # fits swapped, not as given
    assert not (tmp_path / "out").exists()
