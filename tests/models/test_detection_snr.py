"""The site's SNR model as a telemetry design's detection curve
(:meth:`~sblsim.models.design.detection_curve.DetectionCurve.sonar_equation`): the tabulated curve against an
independent numpy evaluation of the passive sonar equation, and its 50 % distance against the sonar module's
detection range."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sblsim.models.acoustics import sonar
from sblsim.models.design.detection_curve import DetectionCurve
from sblsim.models.errors import ModelError

#: Beaufort 2's mid-range wind speed [m/s] (WMO: a light breeze, 1.6–3.3 m/s).
BEAUFORT_2_WIND = 2.5


def _francois_garrison(f_hz: float, t: float, s: float, depth: float = 0.0, ph: float = 8.0) -> float:
    """Francois & Garrison (1982), J. Acoust. Soc. Am. 72(6):1879-1890, eq. (3) with their coefficients, written
    out here again [dB/m]."""
    f = f_hz / 1000.0
    c = 1412.0 + 3.21 * t + 1.19 * s + 0.0167 * depth
    kelvin = 273.0 + t
    a1 = 8.86 / c * 10 ** (0.78 * ph - 5.0)
    f1 = 2.8 * math.sqrt(s / 35.0) * 10 ** (4.0 - 1245.0 / kelvin)
    a2 = 21.44 * s / c * (1.0 + 0.025 * t)
    p2 = 1.0 - 1.37e-4 * depth + 6.2e-9 * depth**2
    f2 = 8.17 * 10 ** (8.0 - 1990.0 / kelvin) / (1.0 + 0.0018 * (s - 35.0))
    a3 = 4.937e-4 - 2.59e-5 * t + 9.11e-7 * t**2 - 1.50e-8 * t**3  # T <= 20 degC
    p3 = 1.0 - 3.83e-5 * depth + 4.9e-10 * depth**2
    boric = a1 * f1 * f**2 / (f1**2 + f**2)
    magnesium = a2 * p2 * f2 * f**2 / (f2**2 + f**2)
    return (boric + magnesium + a3 * p3 * f**2) / 1000.0


def _wenz_band(f_hz: float, band_hz: float, wind: float, shipping: float) -> float:
    """The Wenz curves in Coates' form (Stojanovic 2007, eqs. 6-7), summed as powers, over the band [dB re 1 uPa]."""
    f = f_hz / 1000.0
    levels = [17.0 - 30.0 * math.log10(f),
              40.0 + 20.0 * (shipping - 0.5) + 26.0 * math.log10(f) - 60.0 * math.log10(f + 0.03),
              50.0 + 7.5 * math.sqrt(wind) + 20.0 * math.log10(f) - 40.0 * math.log10(f + 0.4),
              -15.0 + 20.0 * math.log10(f)]
    return 10.0 * math.log10(sum(10 ** (v / 10.0) for v in levels)) + 10.0 * math.log10(band_hz)


def _sonar_equation(d, sl, f, band, wind, shipping, dt, sigma, di, t, s):
    """Urick's passive sonar equation, spherical spreading and absorption, a log-normal fluctuation about DT."""
    r = np.maximum(np.asarray(d, float), 1.0)
    excess = sl - (20.0 * np.log10(r) + _francois_garrison(f, t, s) * r) - (_wenz_band(f, band, wind, shipping) - di)
    return np.array([0.5 * (1.0 + math.erf((x - dt) / (sigma * math.sqrt(2.0)))) for x in excess])


@pytest.mark.parametrize("sl, salinity, temperature, shipping, di", [
    (150.0, 35.0, 10.0, 0.5, 0.0),   # a 69 kHz tag of a middle power class in the sea
    (140.0, 0.0, 15.0, 0.0, 0.0),    # a small tag in a lake (fresh water: the pure water's absorption alone)
    (160.0, 30.0, 4.0, 1.0, 3.0),    # a loud tag, cold water, heavy shipping, a directional hydrophone
])
def test_the_snr_curve_is_the_sonar_equation(sl, salinity, temperature, shipping, di):
    """At 0.5 m (the source level holds at 1 m), 1 m and at 10 %, 30 %, ..., 130 % of its 50 % distance the
    tabulated curve equals the sonar equation evaluated here independently to 1e-4 (its linear interpolation
    between 4,000 rows)."""
    curve = DetectionCurve.sonar_equation(sl, 69000.0, 5000.0, 2, shipping, 12.0, 3.0, di, temperature, salinity)
    r50 = curve.range_at(0.5)
    d = np.r_[0.5, 1.0, r50 * np.array([0.1, 0.3, 0.5, 0.7, 0.9, 1.0, 1.1, 1.3])]
    expected = _sonar_equation(d, sl, 69000.0, 5000.0, BEAUFORT_2_WIND, shipping, 12.0, 3.0, di, temperature,
                               salinity)
    np.testing.assert_allclose(curve.probability(d), expected, atol=1e-4)
    assert expected[-1] < 0.2 < 0.8 < expected[3]  # the distances span the fall
    assert curve.kind == "table" and curve.describe().startswith("SNR model: SL")


@pytest.mark.parametrize("sl, salinity", [(136.0, 35.0), (150.0, 35.0), (165.0, 0.0)])
def test_its_50_percent_distance_is_the_sonar_modules_detection_range(sl, salinity):
    """Where p = 0.5 the mean SNR is the threshold: the curve's 50 % distance equals
    :func:`~sblsim.models.acoustics.sonar.detection_range`'s within 1 %."""
    curve = DetectionCurve.sonar_equation(sl, 69000.0, 5000.0, 2, 0.5, 12.0, 3.0, 0.0, 10.0, salinity)
    expected = sonar.detection_range(69000.0, 5000.0, sl, 0.0, 12.0, BEAUFORT_2_WIND, 0.5, 10.0, salinity, 0.0)
    assert curve.range_at(0.5) == pytest.approx(expected, rel=0.01)


def test_a_tag_heard_nowhere_is_refused_in_one_line():
    with pytest.raises(ModelError, match="^tag.source_level_db: 40 dB .*heard nowhere") as error:
        DetectionCurve.sonar_equation(40.0, 69000.0, 5000.0, 2, 0.5, 12.0, 3.0)
    assert "\n" not in str(error.value)
