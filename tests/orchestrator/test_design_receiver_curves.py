"""A telemetry design with a detection curve per receiver (issue 70 part 1: "per receiver or site-wide"):
``detection.per_receiver`` gives receivers already in place (``candidates.existing_m``) their own range test's
logistic curve, the others hear with the site's. Checked against independent computations: the positioning yield
at every work-area point an exact Poisson-binomial over every detection pattern (each receiver's probability
from its own curve, computed here) and a binomial Monte Carlo of 10⁴ pings; the sync coverage with each receiver
hearing by its own curve; the refusals in one line."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
import tomli_w

import sblsim
from sblsim.models.design.detection_curve import DetectionCurve, ReceiverCurves
from sblsim.orchestrator.cli import main
from tests.helpers import problem_with as _with

L_LAKE = "0 0; 0 300; 150 300; 150 150; 300 150; 300 0"
#: Three receivers in place; two with a range test of their own (a short range: a noisy corner, a weed bed).
MOORED = np.array([[20.0, 20.0], [280.0, 20.0], [20.0, 280.0]])
OWN = {(20.0, 20.0): (60.0, 0.1), (280.0, 20.0): (120.0, 0.05)}
SITE = (350.0, 0.02)
PROBLEM = {
    "design": {"name": "pond"},
    "site": {"area": {"polygon": L_LAKE}},
    "detection": {"range_50_m": SITE[0], "slope": SITE[1], "sync_p": 0.5, "sigma_toa_s": 1e-4,
                  "sound_speed": 1480.0,
                  "per_receiver": "; ".join(f"{n:g} {e:g} {r:g} {s:g}" for (n, e), (r, s) in OWN.items())},
    "work_area": {"shape": "site", "points": 8},
    "prescription": {"drms_m": 2.0, "coverage_pct": 90.0, "positioning_yield_pct": 80.0},
    "candidates": {"systems": ["ilbl"], "receivers": [3, 6],
                   "existing_m": "; ".join(f"{n:g} {e:g}" for n, e in MOORED)},
    "search": {"generations": 6, "seed": 3},
    "monte_carlo": {"replicates": 10, "path": False},
}



def _logistic(d, range_50_m: float, slope: float) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(slope * (np.asarray(d, float) - range_50_m)))


def _probabilities(receivers: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Each receiver's probability of hearing at distances ``d`` (..., n): its own curve where it has one (found
    by its place), else the site's."""
    p = _logistic(d, *SITE)
    for k, r in enumerate(receivers):
        own = OWN.get((float(r[0]), float(r[1])))
        if own is not None:
            p[..., k] = _logistic(d[..., k], *own)
    return p


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    return sblsim.design(None, **PROBLEM, out=tmp_path_factory.mktemp("curves") / "d")


def test_the_yield_at_every_point_is_the_binomial_of_the_receivers_own_curves(result):
    """At every work-area point of the proposed design and of every count searched: the positioning yield (a ping
    heard by at least 3 receivers) equals the sum over every detection pattern of the product of each receiver's
    own probability, to 1e-12; and the curves matter (the site's curve alone gives another yield somewhere)."""
    points = result.run.resolved.points
    differs = 0.0
    for design in result.run.searched:
        receivers = design.receivers
        np.testing.assert_array_equal(receivers[:len(MOORED)], MOORED)  # in place, first
        d = np.linalg.norm(points[:, None] - receivers[None], axis=-1)
        q = _probabilities(receivers, d)
        expected = np.zeros(len(points))
        for bits in itertools.product((False, True), repeat=len(receivers)):
            heard = np.array(bits)
            if heard.sum() >= 3:
                expected += np.prod(np.where(heard, q, 1.0 - q), axis=1)
        np.testing.assert_allclose(design.positioning_yield, expected, rtol=0, atol=1e-12)
        site_only = np.zeros(len(points))
        qs = _logistic(d, *SITE)
        for bits in itertools.product((False, True), repeat=len(receivers)):
            heard = np.array(bits)
            if heard.sum() >= 3:
                site_only += np.prod(np.where(heard, qs, 1.0 - qs), axis=1)
        differs = max(differs, float(np.max(np.abs(site_only - expected))))
    assert differs > 0.01, differs


def test_the_yield_is_a_monte_carlo_of_detections_and_the_simulated_pings_agree(result):
    """At the proposed design's worst and median points: 10⁴ pings, each receiver hearing with its own curve's
    probability (drawn here), heard by ≥ 3 within 2 % of the predicted yield; and the design's own simulated
    pings (its Monte Carlo rows) within 4 binomial sigmas (plus 1 %) of it."""
    best = result.run.best
    rng = np.random.default_rng(8)
    rows = result.designs[0]["monte_carlo"]
    assert rows
    for row in rows:
        point = np.array([row["north_m"], row["east_m"]])
        index = int(np.argmin(np.linalg.norm(result.run.resolved.points - point, axis=1)))
        q = _probabilities(best.receivers, np.linalg.norm(best.receivers - point, axis=1)[None])[0]
        heard = rng.random((10_000, len(q))) < q
        share = float(np.mean(heard.sum(axis=1) >= 3))
        assert abs(share - best.positioning_yield[index]) <= 0.02, (share, best.positioning_yield[index])
        p, n = row["predicted_yield"], row["pings"]
        assert abs(row["simulated_yield"] - p) <= 4.0 * np.sqrt(p * (1 - p) / n) + 0.01, row


def test_each_receiver_hears_the_sync_tags_by_its_own_curve(result):
    """The sync coverage and design.json's sync links: receiver i hears the sync tag at receiver j with i's own
    curve at their distance (computed here), a link where either hears the other with probability ≥ sync_p."""
    best = result.run.best
    receivers = best.receivers
    d = np.linalg.norm(receivers[:, None] - receivers[None], axis=-1)
    q = np.array([_logistic(d[i], *OWN.get((float(r[0]), float(r[1])), SITE)) for i, r in enumerate(receivers)])
    np.fill_diagonal(q, 0.0)
    links = q >= 0.5
    heard = links.sum(axis=1)
    assert np.array_equal(best.sync.heard, heard)
    assert float(best.sync.share) == pytest.approx(np.mean(heard >= 2))
    both = links | links.T
    expected = [[int(i), int(j)] for i, j in zip(*np.nonzero(np.triu(both, 1)))]
    assert result.designs[0]["sync_links"] == expected
    own = [k for k, r in enumerate(receivers) if (float(r[0]), float(r[1])) in OWN]
    assert any(not np.array_equal(links[k], links[:, k]) for k in own)  # direction matters somewhere


def test_receiver_curves_apply_by_column():
    """``ReceiverCurves.probability``: column k by the k-th curve (None: the site's), the others by the site's;
    the site's alone equals the site curve's own, bit for bit."""
    site = DetectionCurve.logistic(*SITE)
    own = DetectionCurve.logistic(60.0, 0.1)
    curves = ReceiverCurves(site, (own, None))
    d = np.array([[10.0, 200.0, 400.0], [80.0, 80.0, 80.0]])
    p = curves.probability(d)
    np.testing.assert_allclose(p[:, 0], _logistic(d[:, 0], 60.0, 0.1), rtol=1e-12)
    np.testing.assert_allclose(p[:, 1:], _logistic(d[:, 1:], *SITE), rtol=1e-12)
    np.testing.assert_array_equal(ReceiverCurves(site).probability(d), site.probability(d))
    assert "1 receiver(s)" in curves.describe()


@pytest.mark.slow
def test_without_per_receiver_curves_the_design_is_the_site_wide_one(tmp_path):
    """No ``detection.per_receiver``: design.json is the same as before the key (the site's curve for every
    receiver) — the same as with every receiver in place given the site's own curve."""
    plain = _with(PROBLEM, detection={"per_receiver": ""}, candidates={"receivers": [3, 4]})
    same = _with(PROBLEM, candidates={"receivers": [3, 4]}, detection={
        "per_receiver": "; ".join(f"{n:g} {e:g} {SITE[0]:g} {SITE[1]:g}" for n, e in MOORED)})
    a = sblsim.design(None, **plain, out=tmp_path / "a").designs
    b = sblsim.design(None, **same, out=tmp_path / "b").designs
    strip = [{k: v for k, v in d.items() if k != "name"} for d in a], [{k: v for k, v in d.items() if k != "name"}
                                                                      for d in b]
    assert json.dumps(strip[0], sort_keys=True) == json.dumps(strip[1], sort_keys=True)


@pytest.mark.parametrize("changes, words", [
    ({"detection": {"per_receiver": "20 20 60"}}, "expected 'north east range_50_m slope"),
    ({"detection": {"per_receiver": "20 20 sixty 0.1"}}, "expected 'north east range_50_m slope"),
    ({"detection": {"per_receiver": "25 20 60 0.1"}}, "no receiver of candidates.existing_m at 25 m North"),
    ({"detection": {"per_receiver": "20 20 60 0.1; 20 20 80 0.1"}}, "two curves for the receiver"),
    ({"detection": {"per_receiver": "20 20 60 0"}}, "detection.per_receiver[0].slope"),
    ({"detection": {"per_receiver": "20 20 60 0.1"}, "candidates": {"existing_m": ""}}, "no receiver of"),
])
def test_a_bad_per_receiver_curve_is_refused_in_one_line(changes, words, tmp_path, capsys):
    """Through ``sblsim design``: one line naming ``detection.per_receiver``, exit status 2, nothing written."""
    path = tmp_path / "problem.toml"
    path.write_text(tomli_w.dumps(_with(PROBLEM, **changes)))
    assert main(["design", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sblsim: error: detection.per_receiver") and words in err, err
    assert len(err.splitlines()) == 1 and not (tmp_path / "o").exists(), err


def test_per_receiver_curves_are_refused_for_another_system(tmp_path, capsys):
    problem = {"design": {"name": "kept", "scenario": "semicircle"}, "candidates": {"systems": ["lbl"]},
               "detection": {"per_receiver": "20 20 60 0.1"}}
    path = tmp_path / "problem.toml"
    path.write_text(tomli_w.dumps(problem))
    assert main(["design", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sblsim: error: detection.per_receiver: for lbl") and len(err.splitlines()) == 1, err
