"""Where a still tag that moved went from one place to the other among the pings without a trusted fix
(:func:`sblsim.models.tracking.still_tag.split_ping`): against every split scored here by scipy's Student-t
log-density, ping by ping."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from sblsim.models.tracking.smoother_cost import ROBUST_DOF
from sblsim.models.tracking.still_tag import split_ping

RECEIVERS = np.array([[0.0, 0.0], [1000.0, 0.0], [1000.0, 800.0], [0.0, 800.0], [500.0, 400.0]])
FIRST, SECOND = np.array([780.0, 560.0]), np.array([800.0, 560.0])
C, SIGMA = 1480.0, 1e-4


def _pings(rng: np.random.Generator, k: int, split: int, heard: float = 0.6) -> np.ndarray:
    """k pings at FIRST before ``split`` and at SECOND from it, each receiver hearing ``heard`` of them, 0.1 ms of
    noise, each ping's emission at a random time."""
    places = np.where((np.arange(k) < split)[:, None], FIRST, SECOND)
    toa = rng.uniform(0, 1e4, k)[:, None] + np.linalg.norm(places[:, None] - RECEIVERS[None], axis=2) / C
    toa = toa + SIGMA * rng.normal(size=toa.shape)
    toa[rng.random(toa.shape) > heard] = np.nan
    return toa


def _best_split_by_scipy(toa: np.ndarray) -> int:
    """The split of the largest Student-t log-likelihood, each ping's residuals about its arrivals' mean (one σ: the
    plain mean), scored by ``scipy.stats.t.logpdf`` in a loop."""
    def loglik(row: np.ndarray, place: np.ndarray) -> float:
        heard = np.isfinite(row)
        emitted = row[heard] - np.linalg.norm(place - RECEIVERS[heard], axis=1) / C
        return float(stats.t.logpdf((emitted - emitted.mean()) / SIGMA, ROBUST_DOF).sum())

    k = len(toa)
    scores = [sum(loglik(toa[j], FIRST) for j in range(s)) + sum(loglik(toa[j], SECOND) for j in range(s, k))
              for s in range(k + 1)]
    return int(np.argmax(scores))


@pytest.mark.parametrize("seed, split", [(0, 0), (1, 7), (2, 13), (3, 20)])
def test_the_split_is_scipys_most_likely_and_the_move(seed, split):
    """20 pings moved at ``split`` (0: all at the second place; 20: none): the split found is the one scipy's
    Student-t log-density scores highest, and the move itself (pings heard by one receiver aside)."""
    toa = _pings(np.random.default_rng(seed), 20, split)
    found = split_ping(toa, RECEIVERS, C, np.full(5, SIGMA), FIRST, SECOND)
    assert found == _best_split_by_scipy(toa)
    informative = np.flatnonzero(np.isfinite(toa).sum(axis=1) >= 2)  # one arrival fits both places alike
    assert (informative[informative < split] < found).all() and (informative[informative >= split] >= found).all()


def test_pings_heard_by_one_receiver_are_flagged_where_nothing_says_they_stayed():
    """Pings heard by one receiver fit both places alike: between two that fit the first place and one that fits the
    second, the earliest split is taken (the uninformative pings flagged)."""
    toa = _pings(np.random.default_rng(4), 6, 2, heard=1.0)
    toa[2:5, 1:] = np.nan  # pings 2 to 4 heard by H1 alone
    assert split_ping(toa, RECEIVERS, C, np.full(5, SIGMA), FIRST, SECOND) == 2
