"""Campaigns on a site's keys (detection by signal-to-noise): a study with the source level, the sea floor and
the sea state as factors runs end to end (``sblsim campaign``, then ``sblsim analyze --metric detected_pct``), each
design cell receives the share of packets the sonar equation predicts, computed here from its terms, and bad
levels stop with one line.

The study holds a diver still at 150 m above the centre of the ``lbl-field`` transponders (all four at the same
slant range, 291 m) in water of a constant 1,500 m/s, where a source level of 140 dB loses packets (the direct
arrival's SNR is a few dB above the threshold at Beaufort 2, below it at Beaufort 6), 160 dB hardly any.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import tomli_w
from scipy.stats import norm

from sblsim.models.acoustics import ambient_noise, volume_absorption
from sblsim.models.acoustics.channel.site_levels import site_levels
from sblsim.orchestrator.campaign.study import load_study
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.metrics import FLAG_NAMES, RUN_METRICS
from sblsim.orchestrator.cosim.run import run

DIVER = np.array([0.0, 0.0, 150.0])
DURATION, REPLICATES = 300.0, 2
STUDY = {
    "study": {"name": "site", "scenarios": ["lbl-field"], "replicates": REPLICATES, "seed": 3,
              "set": [f"simulation.duration={DURATION:g}", "acoustics.sound_speed_profile=constant",
                      "target.trajectory=file", "target.waypoints=0 {0:g} {1:g} {2:g}; 100000 {0:g} {1:g} {2:g}"
                      .format(*DIVER)]},
    "factors": [
        {"name": "SL", "key": "acoustics.source_level", "low": 140.0, "high": 160.0},
        {"name": "bottom", "key": "acoustics.bottom", "low": "sand", "high": "rock"},
        {"name": "sea", "key": "platform.beaufort", "low": 2, "high": 6},
    ],
}


def sblsim(*args, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=600, check=False)


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """The study run and analysed by the commands a user types."""
    folder = tmp_path_factory.mktemp("site")
    (folder / "site.toml").write_text(tomli_w.dumps(STUDY))
    done = sblsim("campaign", "site.toml", "--workers", "1", "--out", "results", cwd=folder)
    assert done.returncode == 0, done.stderr
    done = sblsim("analyze", "results", "--metric", "detected_pct", cwd=folder)
    assert done.returncode == 0, done.stderr
    return folder / "results"


def expected_detected(plan) -> float:
    """The share of the slots whose packet a diver at :data:`DIVER` receives [0–1], from the sonar equation.

    The direct arrival's SNR is SL − (20 log10 r + α r) − (NL − DI) (spherical spreading in constant water;
    α Francois–Garrison averaged over the water column at the declared temperature, NL Wenz, both from
    :mod:`sblsim.models.acoustics.sonar`); the surface- and bottom-reflected arrivals' SNR is the channel's (its
    eigenrays and boundary losses). An arrival is detected with Φ((SNR − DT)/σ_f). A two-way exchange needs the
    interrogation heard (any arrival) and the reply's first detected arrival decoded (Φ((SNR − DT − margin)/σ_f));
    the legs are reciprocal and drawn independently.
    """
    a = plan["acoustics"]
    arms = np.asarray(plan.lever_arms, dtype=float)
    levels = site_levels(plan.component_parameters("acoustics"), arms, np.tile(DIVER, (len(arms), 1)))
    r = np.linalg.norm(arms - DIVER, axis=1)
    depths = np.linspace(0.0, a["water_depth"], 1001)  # the water column's mean: its pressure terms vary with depth
    alpha = float(np.mean([volume_absorption.absorption(a["frequency"], a["temperature"], a["salinity"], d)
                           for d in depths]))
    noise = ambient_noise.noise_level(a["frequency"], a["bandwidth"],
                                      ambient_noise.wind_speed(plan["platform"]["beaufort"]), a["shipping"])
    direct = a["source_level"] - (20.0 * np.log10(r) + alpha * r) - (noise - a["directivity_index"])
    np.testing.assert_allclose(levels["snr"][:, 0], direct, atol=1e-6)  # the channel's direct SNR is the equation's
    snr = np.column_stack([direct, levels["snr"][:, 1:]])
    exists = levels["valid"] > 0.5
    pd_ = np.where(exists, norm.cdf((snr - a["detection_threshold"]) / a["fluctuation"]), 0.0)
    decoded = norm.cdf((snr - a["detection_threshold"] - a["decoding_margin"]) / a["fluctuation"])
    shares = []
    for b in range(len(arms)):
        heard = 1.0 - np.prod(1.0 - pd_[b])
        first, missed = 0.0, 1.0
        for j in np.argsort(np.where(exists[b], levels["tau"][b], np.inf)):  # earliest arrival first
            first += missed * pd_[b, j] * decoded[b, j]
            missed *= 1.0 - pd_[b, j]
        shares.append(heard * first)
    return float(np.mean(shares))  # the slots go round the beacons


@pytest.fixture(scope="module")
def expected():
    """Per design cell: the expected ``detected_pct`` [%]."""
    study = load_study(json.loads(json.dumps(STUDY)))
    return study, np.array([100.0 * expected_detected(study.cell_plan("lbl-field", c)) for c in range(study.cells)])


@pytest.mark.slow
def test_each_cell_receives_the_packets_the_sonar_equation_predicts(campaign, expected):
    study, want = expected
    runs = pd.read_parquet(campaign / "runs.parquet")
    assert len(runs) == study.cells * REPLICATES and {"detected_pct", "slot_overrun"} <= set(runs.columns)
    assert (runs["slot_overrun"] == 0.0).all()  # 0.4 s exchanges in 3 s slots
    # where the question is open at the low source level, and settled at the high one at Beaufort 2
    assert 20.0 < want[0] < 50.0 and want[2] > want[0] + 5.0 and want[1] < 1.0 and want[4] > 99.9
    slots = REPLICATES * round(DURATION / 3.0)
    for cell in range(study.cells):
        got = runs.loc[runs["cell"] == cell, "detected_pct"].mean()
        p = want[cell] / 100.0
        tolerance = 100.0 * (4.0 * math.sqrt(p * (1.0 - p) / slots) + 1.0 / slots)  # binomial, and one slot
        assert abs(got - want[cell]) <= tolerance, (cell, study.cell_overrides(cell), got, want[cell])


@pytest.mark.slow
def test_the_effects_have_the_physical_sign(campaign, expected):
    """A louder source raises the share of packets received, a rougher sea (Wenz: more wind noise) lowers it; the
    analysis's effects are the contrasts of the cell means and its report calls the louder source better."""
    study, want = expected
    runs = pd.read_parquet(campaign / "runs.parquet")
    effects = pd.read_csv(campaign / "effects.csv").set_index("term")["effect"]
    slots = REPLICATES * round(DURATION / 3.0)
    p = want / 100.0
    sd = 100.0 * math.sqrt(np.sum(p * (1.0 - p) / slots)) / (study.cells / 2)  # of a contrast of the cell means
    for name, k in (("SL", 0), ("sea", 2)):
        code = study.matrix[:, k]
        predicted = want[code > 0].mean() - want[code < 0].mean()
        measured = (runs.loc[runs[name] > 0, "detected_pct"].mean() - runs.loc[runs[name] < 0, "detected_pct"].mean())
        assert effects[name] == pytest.approx(measured, abs=1e-9)
        assert abs(predicted) > 10.0 and abs(measured - predicted) < 4.0 * sd + 100.0 / slots, (name, measured,
                                                                                                predicted)
    assert effects["SL"] > 0 > effects["sea"]
    report = (campaign / "report.md").read_text()
    assert "response**: detected_pct (the share of packets received) [%]" in report
    assert "going from 140 dB to 160 dB raises the share of packets received" in report
    assert "the high level (160 dB) is better" in report
    best = runs.groupby("cell")["detected_pct"].mean().idxmax()  # the most packets received: the best cell
    assert f"best cell: {best} (highest mean detected_pct = " in report


@pytest.mark.slow
def test_a_campaign_row_is_the_run_of_its_levels(campaign):
    """A row of a batch of several cells equals the single run of its levels (text levels, and a sea state that
    the channel takes from the platform's key)."""
    runs = pd.read_parquet(campaign / "runs.parquet")
    for k in (1, len(runs) - 1):  # (140 dB, sand, Beaufort 2, replicate 1), (160 dB, rock, Beaufort 6, replicate 1)
        row = runs.iloc[k]
        levels = [row[f["name"] + "_value"] for f in STUDY["factors"]]  # numpy numbers, or text
        overrides = [*STUDY["study"]["set"], *(f"{f['key']}={json.dumps(v.item() if isinstance(v, np.generic) else v)}"
                                               for f, v in zip(STUDY["factors"], levels)),
                     f"run.cell={int(row['cell'])}", f"run.replicate={int(row['replicate'])}"]
        single = run(load_config("lbl-field", overrides, seed=int(row["seed"])), "local").metrics.iloc[0]
        for name in RUN_METRICS + FLAG_NAMES:
            assert single[name] == row[name] or (math.isnan(single[name]) and math.isnan(row[name])), (k, name)


@pytest.mark.parametrize(("change", "needles"), [
    ({"bottom": {"high": "lava"}}, ["factors.bottom.high", "'lava'", "sand", "rock"]),
    *(pytest.param(*case, marks=pytest.mark.slow) for case in [  # a study run each (1 s): one in the fast tier
        ({"SL": {"high": 300.0}}, ["factors.SL.high", "[100, 250] dB"]),
        ({"sea": {"high": 13}}, ["factors.sea.high", "[0, 8]"]),
        ({"scenarios": ["semicircle"]}, ["factors.SL.key", "acoustics.detection", "semicircle"])]),
])
def test_a_bad_site_level_is_one_line_and_writes_nothing(tmp_path, change, needles):
    table = json.loads(json.dumps(STUDY))
    for name, fields in change.items():
        if name == "scenarios":
            table["study"]["scenarios"] = fields
        else:
            next(f for f in table["factors"] if f["name"] == name).update(fields)
    (tmp_path / "bad.toml").write_text(tomli_w.dumps(table))
    done = sblsim("campaign", "bad.toml", "--out", "out", cwd=tmp_path)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("sblsim: error: "), done.stderr
    assert all(n in lines[0] for n in needles), lines[0]
    assert not (tmp_path / "out").exists()
