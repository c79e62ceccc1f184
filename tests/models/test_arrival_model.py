"""The arrival's error with late (multipath) arrivals: its cost, half gradient and observed information against
scipy's own densities (Student's t and the exponentially modified Gaussian, ``scipy.stats.exponnorm``) and their
derivatives by finite differences; the Student-t alone where no arrival is late."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from sblsim.models.tracking.arrival_model import ArrivalModel
from sblsim.models.tracking.smoother_cost import observed_information

Z = np.linspace(-25.0, 60.0, 1701)


def reference_cost(z: np.ndarray, dof: float, share: float, mean: float) -> np.ndarray:
    """``−2 ln p(z)`` from scipy's densities, less its value for a density ``(1 − π) t_ν`` at 0."""
    p = (1 - share) * stats.t.pdf(z, dof) + share * stats.exponnorm.pdf(z, mean)  # K = τ / σ = λ
    return -2.0 * (np.log(p) - np.log((1 - share) * stats.t.pdf(0.0, dof)))


@pytest.mark.parametrize("dof,share,mean", [(3.0, 0.05, 9.0), (10.0, 0.1, 23.0), (10.0, 0.3, 2.0)])
def test_the_cost_and_its_derivatives_are_the_mixture_s(dof, share, mean):
    model = ArrivalModel(dof, share, mean)
    cost, h, g = model.terms(Z)
    np.testing.assert_allclose(cost, reference_cost(Z, dof, share, mean), rtol=1e-9, atol=1e-9)
    e = 1e-4
    slope = (reference_cost(Z + e, dof, share, mean) - reference_cost(Z - e, dof, share, mean)) / (2 * e)
    np.testing.assert_allclose(g, slope / 2, rtol=1e-5, atol=1e-6)
    curvature = (reference_cost(Z + e, dof, share, mean) - 2 * reference_cost(Z, dof, share, mean)
                 + reference_cost(Z - e, dof, share, mean)) / e**2
    np.testing.assert_allclose(model.information(Z), np.maximum(curvature / 2, 0.0), atol=2e-4)
    assert np.all(h > 0.0)
    # one-sided: an arrival late by 10 σ costs less than one early by as much
    late, early = model.terms(np.array([10.0, -10.0]))[0]
    assert late < early


def test_without_late_arrivals_it_is_the_student_t():
    cost, h, g = ArrivalModel(3.0).terms(Z)
    np.testing.assert_allclose(cost, 4.0 * np.log1p(Z**2 / 3.0), atol=1e-12)
    np.testing.assert_allclose(h, 4.0 / (3.0 + Z**2), rtol=1e-12)
    np.testing.assert_allclose(g, h * Z, rtol=1e-12)
    np.testing.assert_allclose(ArrivalModel(3.0).information(Z), observed_information(Z, 3.0), atol=1e-12)


@pytest.mark.parametrize("share,mean", [(1.0, 5.0), (-0.1, 5.0), (0.1, 0.0)])
def test_out_of_range_refused(share, mean):
    with pytest.raises(ValueError, match="delay share"):
        ArrivalModel(3.0, share, mean)
