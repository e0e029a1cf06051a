"""Known values of the aerodynamic model (paper §II-III, CONVENTIONS §2)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flighttest.model import aero


def test_hover_induced_velocity_formula():
    # Mambo: 63 g on 4 rotors of 6.5 cm; CONVENTIONS §1: check the paper's 1.54 m/s against its own formula.
    t = 0.063 * aero.G_MPS2 / 4
    a = math.pi * 0.0325**2
    v_h = float(aero.hover_induced_velocity_mps(t, 1.225, a))
    assert v_h == pytest.approx(math.sqrt(t / (2 * 1.225 * a)))
    assert v_h == pytest.approx(4.359, abs=0.01)


def test_hover_induced_velocity_is_v_h():
    assert float(aero.induced_velocity_n(0.0, 0.0)) == pytest.approx(1.0, abs=1e-12)


def test_climb_and_forward_flight_reduce_induced_velocity():
    lam_climb = float(aero.induced_velocity_n(0.0, 1.0))
    assert lam_climb == pytest.approx((-1 + math.sqrt(5)) / 2, abs=1e-12)  # momentum theory in climb
    assert float(aero.induced_velocity_n(2.0, 0.0)) < 0.5


def test_windmill_branch_is_classical_momentum_theory():
    # At v_H = 0 and v_z = -3 v_h the windmill-brake root of momentum theory is (3 - sqrt(5))/2.
    assert float(aero.induced_velocity_n(0.0, -3.0)) == pytest.approx((3 - math.sqrt(5)) / 2, abs=1e-12)


def test_whole_plane_is_finite_and_solves_peters():
    mu, eta = np.meshgrid(np.linspace(-5, 5, 401), np.linspace(-8, 4, 481))
    lam = aero.induced_velocity_n(mu, eta)
    assert np.isfinite(lam).all()
    assert (lam > 0).all()
    resid = lam * np.sqrt(mu**2 + (lam + eta) ** 2) - 1
    assert np.abs(resid).max() < 1e-10


def test_onera_boundary_at_zero_horizontal_speed():
    eta_edge = -aero.onera_vertical_boundary_n(0.4)
    assert eta_edge == pytest.approx(-0.13485, abs=1e-4)
    lam = float(aero.induced_velocity_n(0.0, eta_edge))
    assert float(aero.onera_epsilon_n(0.0, eta_edge, lam_n=lam)) == pytest.approx(0.4, abs=1e-9)
    # just above: normal; just below: VRS
    assert aero.classify_n(0.0, eta_edge + 1e-3) == aero.Region.NORMAL
    assert aero.classify_n(0.0, eta_edge - 1e-3) == aero.Region.VRS


def test_classification_regions():
    assert aero.classify_n(0.0, 0.5) == aero.Region.NORMAL  # climb
    assert aero.classify_n(0.0, -0.7) == aero.Region.TWS  # deep in the ring at v_H = 0
    assert aero.classify_n(0.0, -3.0) == aero.Region.WBS  # fast straight descent: windmill brake
    assert aero.classify_n(3.0, -0.5) == aero.Region.NORMAL  # shallow fast glide
    # the thresholds are parameters
    assert aero.classify_n(0.0, -0.3) == aero.Region.VRS
    assert aero.classify_n(0.0, -0.3, eps_vrs=0.1, eps_tws=0.05) == aero.Region.NORMAL


def test_guard_bound_and_margin():
    t20 = math.tan(math.radians(20))
    assert aero.guard_bound_mps(0.0, 0.5) == pytest.approx(0.5)
    assert aero.guard_bound_mps(10.0, 0.5) == pytest.approx(10 * t20)
    assert aero.guard_bound_mps(0.0, 0.5, margin_mps=0.1) == pytest.approx(0.4)
    assert aero.guard_bound_mps(0.0, 0.0, margin_mps=0.1) == 0.0  # never below zero
    assert aero.guard_margin_mps(0.6, 0.0, 0.5) == pytest.approx(-0.1)
    arr = aero.guard_margin_mps(np.array([0.2, 1.0]), np.array([0.0, 0.0]), 0.5)
    np.testing.assert_allclose(arr, [0.3, -0.5])


@settings(max_examples=200, deadline=None)
@given(st.floats(0, 10), st.floats(-10, 5))
def test_induced_velocity_scalar_matches_vector(mu, eta):
    lam = float(aero.induced_velocity_n(mu, eta))
    assert math.isfinite(lam) and lam > 0
    assert lam * math.sqrt(mu**2 + (lam + eta) ** 2) == pytest.approx(1.0, abs=1e-9)
