"""A receiver's timing noise from the bins it has data in (issue 98 item 2): the clock's part of ``toa_sigma_s`` is
taken where the receiver's arrivals are (models/sync/noise.py), so a record that runs a second into a last bin (whose
far edge the fit extrapolates to) gives every receiver the noise the simulation drew, as the same record cut before
that bin does. Before: 8 times the drawn noise."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.sync.noise import receiver_noise
from sblsim.orchestrator.telemetry.simulate import simulate_study

#: Each receiver's drawn timing noise [s].
NOISE = np.array([1e-4, 1e-4, 2e-4, 1e-4, 5e-4, 1e-4, 1e-4, 1e-4, 1e-4, 3e-4, 1e-4, 1e-4])


def test_the_clock_part_is_the_offsets_sigma_where_the_arrivals_are():
    """Against a hand computation: two arrivals in the first bin's middle and one at the last bin's start."""
    knots = np.array([[1e-4, 1e-4, 1e-4, 9e-3], [0.0, 0.0, 0.0, 0.0]])
    edges = np.array([0.0, 10.0, 20.0, 30.0])
    receiver = np.array([0, 0, 0, 1])
    time = np.array([5.0, 5.0, 20.1, 5.0])
    noise = receiver_noise(receiver, np.full(4, np.nan), knots, np.array([True, True]), time, edges)
    last = (1 - 0.01) * 1e-4 ** 2 + 0.01 * 9e-3 ** 2
    assert np.isclose(noise.clock[0], np.sqrt((2 * 1e-4 ** 2 + last) / 3), rtol=1e-12)
    assert noise.clock[1] == 0.0
    edge_rms = receiver_noise(receiver, np.full(4, np.nan), knots, np.array([True, True])).clock[0]
    assert np.isclose(edge_rms, np.sqrt((3 * 1e-4 ** 2 + 9e-3 ** 2) / 4)) and edge_rms > 3 * noise.clock[0]


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bins")
    sim = simulate_study(n_receivers=len(NOISE), n_tags=0, days=0.3, redeployed=0, seed=5, sigma_toa=NOISE)
    files = sim.write(folder / "files", "vue")
    whole = sblsim.sync(files["detections"], receivers=files["deployments"], out=folder / "whole")
    return sim, files, folder, whole


def _sigma(folder, sim):
    offsets = pd.read_csv(folder / "offsets.csv", dtype={"receiver": str}).groupby("receiver")["toa_sigma_s"]
    measured = offsets.first()
    serials = sim.clocks["serial"].tolist()
    return measured.to_numpy() / NOISE[[serials.index(r) for r in measured.index]]


def _seconds(files) -> np.ndarray:
    frame = pd.read_csv(files["detections"])
    stamps = pd.to_datetime(frame["Date and Time (UTC)"], utc=True)
    return (stamps - pd.Timestamp("1970-01-01", tz="UTC")).dt.total_seconds().to_numpy()


def _cut(files, seconds: np.ndarray, end: float, folder, name: str):
    """The record's detections up to ``end`` [s since 1970], synchronised into ``folder/name``."""
    text = files["detections"].read_text().splitlines(keepends=True)
    path = folder / f"{name}.csv"
    path.write_text(text[0] + "".join(text[k + 1] for k in np.flatnonzero(seconds <= end)))
    sblsim.sync(path, receivers=files["deployments"], out=folder / name)
    return folder / name


@pytest.mark.slow
def test_a_record_ending_just_into_a_bin_keeps_each_receivers_noise(record, tmp_path):
    """Cut a second after the first emission heard in a bin (its arrivals all in), and 10 s before the bin: each
    receiver's noise the same within 10 %, their median within 0.8-1.25 of the drawn noise (each receiver's alone
    is a few hundred residuals' robust scale)."""
    sim, files, folder, _ = record
    bins = pd.read_csv(folder / "whole" / "offsets.csv")
    edge = float(np.sort(bins["start"].unique())[-2])  # a bin's start [s since 1970], the record going on beyond
    seconds = _seconds(files)
    first = float(np.min(seconds[seconds > edge]))
    into = _sigma(_cut(files, seconds, first + 1.0, tmp_path, "into"), sim)
    before = _sigma(_cut(files, seconds, edge - 10.0, tmp_path, "before"), sim)
    assert first - edge < 900.0  # the record enters the bin by minutes at most
    assert np.all(np.abs(into / before - 1) < 0.1), into / before
    assert 0.8 < np.median(into) < 1.25 and np.all((into > 0.6) & (into < 1.6)), into
