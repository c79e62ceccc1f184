"""The water the tracker takes (models/tracking/sound_speed.py, depth.py): TEOS-10's speed of a stated water and the
speeds it can have, against gsw called here directly; receivers in one plane and the water column's bound on the
tag's depth, against arrays and priors built by hand."""

from __future__ import annotations

import gsw
import numpy as np
import pytest

from sblsim.models.tracking import depth as dp
from sblsim.models.tracking import sound_speed as ss


def _gsw_speed(t, sp, z, lat=None, lon=None):
    """TEOS-10 by hand: the pressure at depth ``z`` [m], the practical salinity made absolute (the atlas at a
    position, else the Reference Salinity), the Conservative Temperature, the speed."""
    p = gsw.p_from_z(-z, 45.0 if lat is None else lat)
    sa = gsw.SR_from_SP(sp) if lat is None else gsw.SA_from_SP(sp, p, lon, lat)
    return gsw.sound_speed(sa, gsw.CT_from_t(sa, t, p), p)


@pytest.mark.parametrize("t,sp,z,lat,lon", [(30.0, 35.0, 1.45, None, None), (4.0, 0.0, 3.0, None, None),
                                             (12.0, 33.0, 40.0, 60.38, 5.33), (25.0, 36.0, 2.0, 25.5, -80.1)])
def test_the_water_speed_is_teos10_of_the_practical_salinity(t, sp, z, lat, lon):
    assert ss.water_speed(t, sp, z, lat, lon) == pytest.approx(_gsw_speed(t, sp, z, lat, lon), abs=1e-9)


def test_the_speeds_the_stated_water_can_have():
    """The middle of the depths crossed, ± 3 σ of 1 °C, 1 in salinity and half the change over the depths."""
    low, high, centre = ss.plausible_speeds(30.0, 35.0, (1.0, 21.0))
    assert centre == pytest.approx(_gsw_speed(30.0, 35.0, 11.0), abs=1e-9)
    along_t = (_gsw_speed(31.0, 35.0, 11.0) - _gsw_speed(29.0, 35.0, 11.0)) / 2
    along_s = (_gsw_speed(30.0, 36.0, 11.0) - _gsw_speed(30.0, 34.0, 11.0)) / 2
    along_z = (_gsw_speed(30.0, 35.0, 21.0) - _gsw_speed(30.0, 35.0, 1.0)) / 2
    half = 3.0 * np.sqrt(along_t**2 + along_s**2 + along_z**2)
    assert (low, high) == pytest.approx((centre - half, centre + half), abs=1e-9)
    # a bay's 30 °C sea water cannot have the 1,511 m/s a free depth calibrated (TEOS-10: about 1,545)
    assert not low <= 1511.0 <= high and low <= 1545.0 <= high
    with pytest.raises(ss.ModelError, match="salinity: 50"):
        ss.plausible_speeds(30.0, 50.0)


#: 8 receivers over 150 x 120 m, 1.1-1.8 m deep (a 2 m bay), and the same 2-20 m deep.
FLAT = np.array([[0.0, 0.0], [150.0, 0.0], [150.0, 120.0], [0.0, 120.0], [75.0, 60.0], [40.0, 110.0],
                 [110.0, 15.0], [20.0, 60.0]])
BAY = np.column_stack([FLAT, -np.array([1.1, 1.8, 1.3, 1.5, 1.2, 1.7, 1.4, 1.6])])
DEEP = np.column_stack([FLAT, -np.array([2.0, 15.0, 4.0, 20.0, 8.0, 3.0, 12.0, 6.0])])


def test_receivers_in_one_plane_hold_the_depth():
    aperture = np.hypot(150.0, 120.0)  # the diagonal: the largest horizontal distance between two
    assert dp.plane_span(BAY) == pytest.approx((0.7, aperture))
    assert dp.in_plane(BAY) and not dp.in_plane(DEEP) and not dp.in_plane(BAY[:, :2])
    held = dp.plane_prior(BAY, sigma=0.3)
    assert (held.depth, held.sigma, held.basis, held.floor) == pytest.approx((1.45, 0.7, "plane", True))
    assert dp.plane_prior(BAY, sigma=2.0).sigma == 2.0  # never surer than a depth reading
    mid = dp.plane_prior(BAY, water_depth=2.0)
    # the uniform over [0, 2] m: its mean and standard deviation
    assert (mid.depth, mid.sigma) == pytest.approx((1.0, np.sqrt(np.mean((np.linspace(0, 2, 200001) - 1) ** 2))),
                                                   rel=1e-4)
    assert dp.plane_prior(DEEP) is None


def test_the_water_column_bounds_any_prior():
    column = dp.bounded_prior(None, 30.0, fixes=12)
    assert (column.depth, column.sigma, column.floor, column.fixes) == pytest.approx((15.0, 30 / np.sqrt(12), False,
                                                                                       12))
    wide = dp.DepthPrior(depth=3.0, sigma=20.0, ratio=2.2, fixes=40)
    assert (dp.bounded_prior(wide, 10.0).depth, dp.bounded_prior(wide, 10.0).sigma) == pytest.approx(
        (5.0, 10 / np.sqrt(12)))
    assert dp.bounded_prior(wide, 10.0).floor and dp.bounded_prior(wide, 10.0).ratio == 2.2
    narrow = dp.DepthPrior(depth=12.0, sigma=1.0, ratio=0.7, fixes=40)
    assert dp.bounded_prior(narrow, 10.0).depth == 10.0 and dp.bounded_prior(narrow, 10.0).sigma == 1.0
    assert dp.bounded_prior(narrow, None) is narrow
