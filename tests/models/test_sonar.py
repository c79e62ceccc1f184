"""The sonar equation's terms (``sblsim.models.acoustics.sonar``) against references nobody here wrote.

* Absorption against Bellhop's Francois-Garrison volume attenuation (the Acoustics Toolbox's ``Franc_Garr``,
  M. Porter, checked there against Francois & Garrison 1982, Table IV), run through ``pelagic`` (test-only):
  the imaginary part of a direct arrival's delay gives Bellhop's attenuation. Within 1 %. And against
  Ainslie & McColm (J. Acoust. Soc. Am. 103(3):1671-1672, 1998), a different fit, within the 10 % they state.
* Ambient noise: the closed-form slopes and limits of each Wenz/Coates term, the power sum's bounds.
* Bottom loss against numpy complex arithmetic written here, its lossless limits, and Bellhop's
  bottom-reflected arrivals (their amplitude times the path length over the direct arrival's).
* Surface loss, detection probability (against ``scipy.stats.norm``), accuracy scale: closed forms.
* The hand-worked detection range of docs/model.md: every number of its table recomputed here in numpy, and
  the range solved here with ``scipy.optimize.brentq``.
"""

from __future__ import annotations

import math
import os
import re
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.stats import norm

from sblsim.models.acoustics import ambient_noise, boundary_loss, sonar, volume_absorption
from sblsim.models.errors import ModelError
from sblsim.models.platform.waves import WAVE_HEIGHT, WIND_SPEED

ROOT = Path(__file__).resolve().parents[2]

# ------------------------------------------------------------------ absorption

#: (frequency [Hz], temperature [°C], salinity [PSU], depth [m], pH): cold and warm water (both branches of the
#: pure-water term), shallow and deep, the boric-acid, magnesium-sulphate and pure-water regimes.
CASES = [(1e3, 4.0, 35.0, 1000.0, 8.0), (10e3, 10.0, 35.0, 0.0, 8.0), (25e3, 10.0, 35.0, 500.0, 8.0),
         (50e3, 15.0, 34.0, 100.0, 7.9), (100e3, 25.0, 36.0, 50.0, 8.1), (300e3, 22.0, 35.0, 20.0, 8.0),
         (12e3, 2.0, 33.0, 3000.0, 7.8)]


def _bellhop_absorption(frequency, temperature, salinity, depth, ph):
    """Bellhop's Francois-Garrison attenuation [dB/m]: a direct path of 1 km in deep isovelocity water."""
    pg = pytest.importorskip("pelagic")  # the test extra installs it: this skips only outside it
    lines = ["'fg'", f"{frequency}", "1", "'CVWF'", f"{temperature} {salinity} {ph} {depth} /",
             "0 0.0 5000.0", "0.0 1500.0 /", "5000.0 1500.0 /", "'A' 0.0", "5000.0 1500.0 0.0 1.0 0.0 /",
             "1", "2500.0 /", "1", "2500.0 /", "1", "1.0 /", "'A'", "201", "-1 1 /", "10 5100.0 2"]
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "case.env")
        with open(path, "w") as handle:
            handle.write("\n".join(lines) + "\n")
        arrivals = pg.bellhop.load(path).run().arrivals.to_pandas()
    direct = arrivals[(arrivals.top_bounces == 0) & (arrivals.bottom_bounces == 0)]
    delay = direct.attenuation_time_s.to_numpy()[np.argmax(direct.amplitude.to_numpy())]
    # |p| ∝ exp(−ω |Im τ|): nepers over the 1000 m path, in dB/m
    return 20.0 / math.log(10.0) * 2.0 * math.pi * frequency * abs(delay) / 1000.0


@pytest.mark.parametrize("case", CASES)
def test_absorption_matches_bellhop_francois_garrison(case):
    ours = volume_absorption.absorption(*case)
    reference = _bellhop_absorption(*case)
    assert ours == pytest.approx(reference, rel=0.01)


def _ainslie_mccolm(frequency, temperature, salinity, depth, ph):
    """Ainslie & McColm (1998) [dB/km], f in kHz, depth in km."""
    f, t, s, z = frequency / 1000.0, temperature, salinity, depth / 1000.0
    f1 = 0.78 * math.sqrt(s / 35.0) * math.exp(t / 26.0)
    f2 = 42.0 * math.exp(t / 17.0)
    boric = 0.106 * f1 * f * f / (f1 * f1 + f * f) * math.exp((ph - 8.0) / 0.56)
    mgso4 = 0.52 * (1.0 + t / 43.0) * (s / 35.0) * f2 * f * f / (f2 * f2 + f * f) * math.exp(-z / 6.0)
    water = 0.00049 * f * f * math.exp(-(t / 27.0 + z / 17.0))
    return boric + mgso4 + water


@pytest.mark.parametrize("case", CASES)
def test_absorption_within_ten_percent_of_ainslie_mccolm(case):
    assert 1000.0 * volume_absorption.absorption(*case) == pytest.approx(_ainslie_mccolm(*case), rel=0.10)


def test_absorption_symbolic_equals_float_on_both_branches():
    x = ca.SX.sym("x", 5)
    f = ca.Function("alpha", [x], [volume_absorption.absorption(x[0], x[1], x[2], x[3], x[4])])
    for case in CASES:
        assert float(f(case)) == pytest.approx(volume_absorption.absorption(*case), rel=1e-14)
    assert isinstance(volume_absorption.absorption(25e3, 10.0, 35.0, 0.0), float)
    # the pure-water term switches at 20 °C: 3.964e-4 − ... above, the cold polynomial at 20 °C exactly
    cold = 4.937e-4 - 2.59e-5 * 20 + 9.11e-7 * 400 - 1.5e-8 * 8000
    warm = 3.964e-4 - 1.146e-5 * 20.001 + 1.45e-7 * 20.001**2 - 6.5e-10 * 20.001**3
    at_1mhz = volume_absorption.absorption(1e6, 20.0, 0.0, 0.0) * 1000  # S = 0: only pure water is left
    assert at_1mhz == pytest.approx(cold * 1e6, rel=1e-12)
    assert volume_absorption.absorption(1e6, 20.001, 0.0, 0.0) * 1000 == pytest.approx(warm * 1e6, rel=1e-12)


# ------------------------------------------------------------------ ambient noise


def test_noise_terms_slopes_and_limits():
    f_lo, f_hi = 1e5, 1e6  # one decade, far above the knees at 0.03 and 0.4 kHz
    lo = ambient_noise.noise_components(f_lo, 4.4, 0.5)
    hi = ambient_noise.noise_components(f_hi, 4.4, 0.5)
    slopes = [h - low for h, low in zip(hi, lo)]
    assert slopes[0] == pytest.approx(-30.0, abs=1e-9)  # turbulence: −30 dB/decade exactly
    assert slopes[3] == pytest.approx(20.0, abs=1e-9)  # thermal: +20 dB/decade exactly
    assert slopes[1] == pytest.approx(26.0 - 60.0 * math.log10(1000.03 / 100.03), abs=1e-9)
    assert slopes[1] == pytest.approx(-34.0, abs=0.01)  # shipping tends to 26 − 60
    assert slopes[2] == pytest.approx(20.0 - 40.0 * math.log10(1000.4 / 100.4), abs=1e-9)
    assert slopes[2] == pytest.approx(-20.0, abs=0.1)  # wind tends to 20 − 40
    # shipping: 20 dB from none to heavy; wind: 7.5 (√w2 − √w1)
    assert (ambient_noise.noise_components(3e3, 4.4, 1.0)[1] - ambient_noise.noise_components(3e3, 4.4, 0.0)[1]
            == pytest.approx(20))
    w1, w2 = 2.5, 12.3
    assert (ambient_noise.noise_components(3e3, w2, 0.5)[2] - ambient_noise.noise_components(3e3, w1, 0.5)[2]
            == pytest.approx(7.5 * (math.sqrt(w2) - math.sqrt(w1))))
    # values at 1 kHz written out: log f = 0
    t, s, w, th = ambient_noise.noise_components(1e3, 4.0, 0.5)
    assert (t, th) == (pytest.approx(17.0), pytest.approx(-15.0))
    assert s == pytest.approx(40.0 - 60.0 * math.log10(1.03))
    assert w == pytest.approx(50.0 + 15.0 - 40.0 * math.log10(1.4))


@pytest.mark.parametrize("frequency", [10.0, 100.0, 1e3, 1e4, 3e4, 1e5, 1e6])
@pytest.mark.parametrize("wind", WIND_SPEED)
@pytest.mark.parametrize("shipping", [0.0, 0.5, 1.0])
def test_noise_sum_between_largest_and_largest_plus_6db(frequency, wind, shipping):
    levels = ambient_noise.noise_components(frequency, wind, shipping)
    total = ambient_noise.noise_spectrum_level(frequency, wind, shipping)
    assert max(levels) <= total <= max(levels) + 10.0 * math.log10(4.0) + 1e-12
    assert total == pytest.approx(10.0 * np.log10(np.sum(10.0 ** (np.array(levels) / 10.0))), abs=1e-10)


def test_noise_level_adds_the_band():
    for bandwidth in (1.0, 100.0, 5e3):
        band = ambient_noise.noise_level(25e3, bandwidth, 4.4, 0.5) - ambient_noise.noise_spectrum_level(25e3, 4.4, 0.5)
        assert band == pytest.approx(10.0 * math.log10(bandwidth), abs=1e-12)


@pytest.mark.parametrize("centre", [10e3, 25e3, 50e3])
@pytest.mark.parametrize("wind", [0.1, 4.4, 18.95])
def test_noise_level_of_a_band_within_005_db_of_the_integrated_spectrum(centre, wind):
    """docs/model.md: for B/f_c = 0.2 the centre's spectrum level stands for the band within 0.05 dB."""
    f = np.linspace(0.9 * centre, 1.1 * centre, 2001)
    power = np.array([10.0 ** (ambient_noise.noise_spectrum_level(x, wind, 0.5) / 10.0) for x in f])
    integrated = 10.0 * np.log10(np.trapezoid(power, f))
    assert abs(integrated - ambient_noise.noise_level(centre, 0.2 * centre, wind, 0.5)) < 0.05


def test_beaufort_tables_are_the_platforms():
    assert [ambient_noise.wind_speed(b) for b in range(9)] == list(WIND_SPEED)
    assert [boundary_loss.wave_height(b) for b in range(9)] == list(WAVE_HEIGHT)


# ------------------------------------------------------------------ bottom


def _numpy_bottom_loss(grazing, density_ratio, speed_ratio, attenuation):
    """−20 log10 |R| with numpy complex numbers: k_b = (ω/c_b)(1 + iδ), δ = α/(40π log10 e), Im k_zb ≥ 0."""
    delta = attenuation / (40.0 * np.pi * np.log10(np.e))
    n = (1.0 + 1j * delta) / speed_ratio
    kz_b = np.sqrt(n * n - np.cos(grazing) ** 2 + 0j)
    kz_b = np.where(kz_b.imag < 0, -kz_b, kz_b)
    r = (density_ratio * np.sin(grazing) - kz_b) / (density_ratio * np.sin(grazing) + kz_b)
    return -20.0 * np.log10(np.abs(r))


@pytest.mark.parametrize("name", sorted(boundary_loss.BOTTOMS))
def test_bottom_loss_matches_numpy_complex(name):
    row = boundary_loss.BOTTOMS[name]
    for water in (1480.0, 1500.0, 1530.0):
        for grazing in np.radians([0.01, 0.5, 2.0, 10.0, 17.0, 24.0, 25.0, 33.0, 45.0, 60.0, 75.0, 89.9, 90.0]):
            expected = _numpy_bottom_loss(grazing, row.density_ratio, row.speed / water, row.attenuation)
            ours = boundary_loss.bottom_loss(float(grazing), name, water)
            assert ours == pytest.approx(expected, abs=1e-9)
            assert ours >= 0.0


def test_bottom_loss_lossless_limits():
    m, nu = 1.9, 1.1
    critical = math.acos(1.0 / nu)
    for grazing in np.linspace(0.0, critical - 1e-6, 25):
        assert boundary_loss.half_space_loss(float(grazing), m, nu, 0.0) == pytest.approx(0.0, abs=1e-9)
    normal = -20.0 * math.log10(abs((m * nu - 1.0) / (m * nu + 1.0)))
    assert boundary_loss.half_space_loss(math.pi / 2, m, nu, 0.0) == pytest.approx(normal, rel=1e-12)
    assert boundary_loss.half_space_loss(critical + 0.05, m, nu, 0.0) > 0.1  # energy leaves above the critical angle
    # attenuation takes energy also below it
    assert boundary_loss.half_space_loss(critical / 2, m, nu, 0.8) > 0.1
    # a bottom like the water reflects nothing at normal incidence: R = 0 (infinite loss, finite number)
    assert boundary_loss.half_space_loss(math.pi / 2, 1.0, 1.0, 0.0) > 100.0


def test_bottom_loss_symbolic_equals_float():
    g, m, nu, a = (ca.SX.sym(n) for n in ("g", "m", "nu", "a"))
    f = ca.Function("bl", [g, m, nu, a], [boundary_loss.half_space_loss(g, m, nu, a)])
    for row in boundary_loss.BOTTOMS.values():
        for grazing in (0.0, 0.1, 0.5, 1.2, math.pi / 2):
            expected = boundary_loss.half_space_loss(grazing, row.density_ratio, row.speed / 1500.0, row.attenuation)
            assert float(f(grazing, row.density_ratio, row.speed / 1500.0, row.attenuation)) == pytest.approx(
                expected, abs=1e-12)


def test_bottom_table_names_and_errors():
    assert {"mud", "sand", "gravel", "rock"} <= set(boundary_loss.BOTTOMS)
    bottoms = boundary_loss.BOTTOMS
    assert bottoms["mud"] == bottoms["clay"] and bottoms["rock"] == bottoms["limestone"]
    assert boundary_loss.bottom_parameters("sand") == (1.9, 1.1, 0.8)
    assert boundary_loss.bottom_parameters((1.8, 1600.0, 0.5), 1600.0) == (1.8, 1.0, 0.5)
    with pytest.raises(ModelError, match=r"^acoustics.bottom: unknown bottom 'lava' \(allowed: clay, .*rock\)$"):
        boundary_loss.bottom_loss(0.3, "lava")
    for bad, field in (((0.0, 1600.0, 0.5), "density ratio"), ((1.8, -1.0, 0.5), "speed"),
                       ((1.8, 1600.0, -0.1), "attenuation"), ((1.8, float("nan"), 0.5), "speed")):
        with pytest.raises(ModelError, match=f"^acoustics.bottom: {field}"):
            boundary_loss.bottom_parameters(bad)
    with pytest.raises(ModelError, match="^acoustics.bottom"):
        boundary_loss.bottom_parameters((1.0, 2.0))


def _bellhop_bottom_arrivals(row, ranges, depth=100.0, zs=50.0):
    pg = pytest.importorskip("pelagic")
    lines = ["'br'", "25000.0", "1", "'CVW'", f"0 0.0 {depth}", "0.0 1500.0 /", f"{depth} 1500.0 /",
             "'A' 0.0", f"{depth} {row.speed} 0.0 {row.density_ratio} {row.attenuation} /", "1", f"{zs} /",
             "1", f"{zs} /", f"{len(ranges)}", " ".join(f"{r / 1000:.6f}" for r in ranges) + " /", "'AB'",
             "3001", "-60 60 /", f"5 {depth + 10} {max(ranges) / 1000 + 0.1}"]
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "case.env")
        with open(path, "w") as handle:
            handle.write("\n".join(lines) + "\n")
        return pg.bellhop.load(path).run().arrivals.to_pandas()


@pytest.mark.parametrize("name", ["mud", "silt", "sand", "gravel", "rock"])
def test_bottom_loss_matches_bellhop(name):
    """|R| = (bottom-bounce amplitude × its path length) / (direct amplitude × range) in isovelocity water:
    Bellhop's beams of one eigenray summed (equal delays), source and receiver at 50 m in 100 m of water."""
    ranges = [100.0, 200.0, 300.0, 500.0, 800.0, 1200.0, 2000.0]
    arrivals = _bellhop_bottom_arrivals(boundary_loss.BOTTOMS[name], ranges)
    for r in ranges:
        here = arrivals[arrivals.range_m == r]
        bounce_length = math.hypot(r, 100.0)

        def amplitude(rows, length):
            rows = rows[np.abs(rows.travel_time_s - length / 1500.0) < 2e-4]
            return rows.amplitude.sum()

        direct = amplitude(here[(here.top_bounces == 0) & (here.bottom_bounces == 0)], r)
        bounce = amplitude(here[(here.top_bounces == 0) & (here.bottom_bounces == 1)], bounce_length)
        bellhop = -20.0 * math.log10(bounce * bounce_length / (direct * r))
        assert boundary_loss.bottom_loss(math.atan2(100.0, r), name) == pytest.approx(bellhop, abs=0.1), r


# ------------------------------------------------------------------ surface


def test_surface_loss_rayleigh_roughness():
    grazing, f, h = math.radians(10.0), 25e3, 0.6
    sigma = h / 4.0
    k = 2.0 * math.pi * f / 1500.0
    expected = -20.0 * math.log10(math.exp(-2.0 * (k * sigma * math.sin(grazing)) ** 2))
    assert boundary_loss.surface_loss(grazing, f, h) == pytest.approx(expected, rel=1e-12)
    assert boundary_loss.surface_loss(0.0, f, h) == 0.0  # grazing: the specular path keeps its energy
    assert boundary_loss.surface_loss(grazing, f, 0.0) == 0.0  # a flat sea
    # quadratic in frequency and in wave height
    assert boundary_loss.surface_loss(grazing, 2 * f, h) == pytest.approx(4.0 * expected, rel=1e-12)
    assert boundary_loss.surface_loss(grazing, f, 2 * h) == pytest.approx(4.0 * expected, rel=1e-12)
    assert boundary_loss.surface_loss(grazing, f, h, limit=30.0) == 30.0
    assert boundary_loss.surface_loss(grazing, 1e3, 0.1, limit=30.0) < 30.0


# ------------------------------------------------------------------ sonar equation, detection, accuracy


def test_snr_is_the_sonar_equation():
    assert sonar.snr(180.0, 93.5, 74.5, 0.0) == pytest.approx(12.0)
    assert sonar.snr(180.0, 93.5, 74.5, 6.0) == pytest.approx(18.0)  # directivity rejects noise


def test_detection_probability():
    for excess in (-6.0, -1.0, 0.0, 0.5, 3.0):
        for sigma in (0.5, 2.0, 5.0):
            assert sonar.detection_probability(12.0 + excess, 12.0, sigma) == pytest.approx(
                norm.cdf(excess / sigma), abs=1e-12)
    assert sonar.detection_probability(12.0, 12.0, 0.0) == 1.0  # the step: heard at the threshold
    assert sonar.detection_probability(11.999, 12.0, 0.0) == 0.0
    assert sonar.detection_probability(30.0, 12.0, 0.0) == 1.0
    s, dt, sigma = ca.SX.sym("s"), ca.SX.sym("dt"), ca.SX.sym("sigma")
    pd = sonar.detection_probability(s, dt, sigma)
    f = ca.Function("pd", [s, dt, sigma], [pd, ca.jacobian(pd, s)])
    value, slope = f(13.0, 12.0, 0.0)
    assert float(value) == 1.0 and math.isfinite(float(slope))
    value, slope = f(12.0, 12.0, 2.0)
    assert float(value) == pytest.approx(0.5) and float(slope) == pytest.approx(norm.pdf(0.0) / 2.0)


def test_accuracy_scale_doubles_per_6db():
    assert sonar.accuracy_scale(20.0) == 1.0
    assert sonar.accuracy_scale(35.0) == 1.0  # the configured σ is the floor above the reference
    six = 20.0 * math.log10(2.0)
    assert sonar.accuracy_scale(20.0 - six) == pytest.approx(2.0, rel=1e-12)
    assert sonar.accuracy_scale(20.0 - 2 * six) == pytest.approx(4.0, rel=1e-12)
    assert sonar.accuracy_scale(10.0, reference_snr=16.0) == pytest.approx(10 ** 0.3, rel=1e-12)
    snr = ca.SX.sym("snr")
    assert float(ca.Function("a", [snr], [sonar.accuracy_scale(snr)])(8.0)) == pytest.approx(10 ** 0.6)


# ------------------------------------------------------------------ the hand-worked detection range


def _doc_values() -> dict[str, str]:
    """The values column of docs/model.md's worked detection range (rows ``| `key` | ... | value |``)."""
    text = (ROOT / "docs" / "model.md").read_text(encoding="utf-8")
    section = text.split("**A detection range worked by hand.**", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `(\w+)` \|[^\n]*\| (-?[0-9.]+) \|$", section, flags=re.M)
    return dict(rows)


def test_hand_worked_detection_range():
    doc = _doc_values()
    f, bandwidth, sl, di, dt, s_, t, sal, d, ph = 25.0, 5e3, 180.0, 0.0, 12.0, 0.5, 10.0, 35.0, 500.0, 8.0
    w = WIND_SPEED[3]
    # Francois-Garrison and Coates written out again here (numpy), f in kHz
    c = 1412 + 3.21 * t + 1.19 * sal + 0.0167 * d
    theta = 273 + t
    a1, f1 = 8.86 / c * 10 ** (0.78 * ph - 5), 2.8 * np.sqrt(sal / 35) * 10 ** (4 - 1245 / theta)
    a2, p2 = 21.44 * sal / c * (1 + 0.025 * t), 1 - 1.37e-4 * d + 6.2e-9 * d**2
    f2 = 8.17 * 10 ** (8 - 1990 / theta) / (1 + 0.0018 * (sal - 35))
    a3, p3 = 4.937e-4 - 2.59e-5 * t + 9.11e-7 * t**2 - 1.5e-8 * t**3, 1 - 3.83e-5 * d + 4.9e-10 * d**2
    boric, mgso4, water = a1 * f1 * f**2 / (f1**2 + f**2), a2 * p2 * f2 * f**2 / (f2**2 + f**2), a3 * p3 * f**2
    alpha = boric + mgso4 + water
    levels = np.array([17 - 30 * np.log10(f), 40 + 20 * (s_ - 0.5) + 26 * np.log10(f) - 60 * np.log10(f + 0.03),
                       50 + 7.5 * np.sqrt(w) + 20 * np.log10(f) - 40 * np.log10(f + 0.4), -15 + 20 * np.log10(f)])
    nl_f = 10 * np.log10(np.sum(10 ** (levels / 10)))
    nl = nl_f + 10 * np.log10(bandwidth)
    tl_max = sl - (nl - di) - dt
    r = brentq(lambda x: 20 * np.log10(x) + alpha / 1000 * x - tl_max, 1.0, 1e6, xtol=1e-9)
    ours = {"w": w, "c": c, "A1": a1, "f1": f1, "A2": a2, "P2": p2, "f2": f2, "A3": a3, "P3": p3,
            "alpha_boric": boric, "alpha_mgso4": mgso4, "alpha_water": water, "alpha": alpha, "N_t": levels[0],
            "N_s": levels[1], "N_w": levels[2], "N_th": levels[3], "NL_f": nl_f, "band": 10 * np.log10(bandwidth),
            "NL": nl, "TL_max": tl_max, "range": r, "spreading": 20 * np.log10(r), "absorption": alpha / 1000 * r}
    assert set(doc) == set(ours)
    for key, value in ours.items():  # the doc's number is the value rounded to the digits it prints
        digits = len(doc[key].split(".")[1]) if "." in doc[key] else 0
        assert abs(float(doc[key]) - value) <= 0.5 * 10.0**-digits + 1e-12 * abs(value), (key, doc[key], value)
    # the module gives the same terms and range
    assert 1000 * volume_absorption.absorption(25e3, t, sal, d, ph) == pytest.approx(alpha, rel=1e-12)
    assert ambient_noise.noise_level(25e3, bandwidth, ambient_noise.wind_speed(3), s_) == pytest.approx(nl, abs=1e-10)
    found = sonar.detection_range(25e3, bandwidth, sl, di, dt, ambient_noise.wind_speed(3), s_, t, sal, d, ph)
    assert found == pytest.approx(r, rel=1e-8)
    assert found == pytest.approx(float(doc["range"]), rel=0.05)
    # SNR at that range is the threshold
    tl = 20 * math.log10(found) + volume_absorption.absorption(25e3, t, sal, d, ph) * found
    assert sonar.snr(sl, tl, nl, di) == pytest.approx(dt, abs=1e-6)


def test_detection_range_grows_with_source_level_and_refuses_unheard():
    args = dict(frequency=25e3, bandwidth=5e3, directivity_index=0.0, detection_threshold=12.0, wind_speed=4.4,
                shipping=0.5, temperature=10.0, salinity=35.0, depth=500.0)
    ranges = [sonar.detection_range(source_level=sl, **args) for sl in (160.0, 180.0, 200.0)]
    assert ranges[0] < ranges[1] < ranges[2]
    # noisier sea (Beaufort 6), shorter range
    assert sonar.detection_range(source_level=180.0, **{**args, "wind_speed": 12.3}) < ranges[1]
    with pytest.raises(ModelError, match="^detection_range: SNR at 1 m is below"):
        sonar.detection_range(source_level=80.0, **args)
