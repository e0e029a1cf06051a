"""The wind estimate from the drag across the thrust axis (``flighttest.model.wind_estimate``), in virtual
time: synthetic samples of a vehicle whose drag the filter knows within its stated uncertainty."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flighttest.model.drag import DragModel
from flighttest.model.frames import ned_to_body, quat_from_euler
from flighttest.model.wind_estimate import WindFilter

SIH = (DragModel((1.0, 1.0), (0.0, 0.0), 0.05, "SIH_KDV"), 1.0)
ARDUCOPTER = (DragModel((0.745, 0.745), (0.1, 0.1), 0.15, "SIM_Frame"), 3.0)


def fly(drag_true: DragModel, mass_kg: float, drag_known: DragModel, wind=(0.0, 3.0, 0.0), seconds=10.0,
        noise_mps2=0.2, seed=0, circle_mps=1.5) -> WindFilter:  # fmt: skip
    """Hover 5 s, then a circle at ``circle_mps``; the IMU feels ``drag_true``, the filter knows ``drag_known``."""
    rng = np.random.default_rng(seed)
    f = WindFilter(drag_known, mass_kg)
    w = np.asarray(wind, float)
    for k in range(int(seconds / 0.02)):
        t = k * 0.02
        v = np.array([circle_mps * math.cos(t), circle_mps * math.sin(t), 0.3]) if t > 5 else np.zeros(3)
        q = quat_from_euler(0.05, -0.1, 0.3 + 0.1 * t)
        bx, by, _ = ned_to_body(*(v - w), *q)
        fx, fy = drag_true.force_n(bx, by)
        f.update(t, tuple(v), tuple(q), (fx / mass_kg + rng.normal() * noise_mps2,
                                         fy / mass_kg + rng.normal() * noise_mps2))  # fmt: skip
    return f


@pytest.mark.parametrize(("drag", "mass_kg"), [SIH, ARDUCOPTER])
@pytest.mark.parametrize("wind", [(0.0, 3.0, 0.0), (-2.1, -2.1, 0.0), (0.0, 0.0, 0.0)])
def test_the_wind_is_found_within_its_stated_uncertainty(drag, mass_kg, wind):
    f = fly(drag, mass_kg, drag, wind)
    err = math.hypot(f.wn_mps - wind[0], f.we_mps - wind[1])
    assert err < 2.0 * f.sd_mps and f.sd_mps < 0.7  # the drag model's 15 % of 3.8 m/s of air, at most


def test_a_drag_model_off_by_its_stated_uncertainty_is_still_covered():
    # the vehicle drags 15 % more than the profile says, which its rel_sd 0.15 admits
    drag, m = ARDUCOPTER
    true = DragModel((0.745 * 1.15, 0.745 * 1.15), (0.115, 0.115), 0.0, "truth")
    f = fly(true, m, drag)
    assert math.hypot(f.wn_mps, f.we_mps - 3.0) < 2.45 * f.sd_mps


def test_an_assumed_drag_model_says_it_knows_little_in_a_hover():
    drag, m = SIH
    assumed = DragModel.isotropic_linear(1.0)  # ±50 %
    f = fly(drag, m, assumed, circle_mps=0.0)
    assert f.sd_mps > 1.0  # 50 % of a 3 m/s airspeed: a steady airspeed cannot tell the wind from the scale


def test_changing_air_teaches_it_the_drags_scale():
    """The vehicle drags 15 % more than a model known to ±15 %: a circle under a steady wind tells the two
    apart, and the filter finds the scale, the wind, and knows them better than in the hover."""
    _, m = SIH
    true = DragModel.isotropic_linear(1.15, 0.0, "truth")
    known = DragModel.isotropic_linear(1.0, 0.15, "identified")
    hover = fly(true, m, known, circle_mps=0.0, seconds=15.0)
    assert hover.scale_error == 0.0  # a steady velocity: nothing to learn it from
    f = fly(true, m, known, circle_mps=1.5, seconds=15.0)
    assert f.scale_error == pytest.approx(0.15, abs=0.05) and f.scale_sd < 0.1
    err = math.hypot(f.wn_mps, f.we_mps - 3.0)
    assert err < 0.3 and err < 2.45 * f.sd_mps and f.sd_mps < 0.5 * hover.sd_mps


def test_nothing_known_before_the_first_sample():
    f = WindFilter(SIH[0], 1.0)
    assert f.sd_mps == 5.0 and f.wind_ned_mps == (0.0, 0.0, 0.0)
    f.update(0.0, (math.nan, 0, 0), (1, 0, 0, 0), (0, 0))  # a non-finite sample is skipped
    assert f.samples == 0


def hover_with_bias(turn_deg: float, wind=(0.0, 0.0), bias=(0.05, -0.05), seconds=8.0, seed=1) -> WindFilter:
    """The runner's climb (5 s at 1 m/s, the heading swung out by ``turn_deg`` and back), then a hover; the
    x500-like drag (slope 0.26 /s), the IMU with a body-fixed bias."""
    drag, m = DragModel.isotropic_linear(0.52, 0.1), 2.0
    rng = np.random.default_rng(seed)
    f = WindFilter(drag, m)
    for k in range(int(seconds / 0.02)):
        t = k * 0.02
        yaw = math.radians(turn_deg) * 0.5 * (1.0 - math.cos(2.0 * math.pi * min(t / 5.0, 1.0)))
        q = quat_from_euler(0.0, 0.0, yaw)
        v = (0.0, 0.0, -1.0 if t < 5.0 else 0.0)
        bx, by, _ = ned_to_body(v[0] - wind[0], v[1] - wind[1], v[2], *q)
        fx, fy = drag.force_n(bx, by)
        f.update(t, v, tuple(q), (fx / m + bias[0] + 0.07 * rng.normal(), fy / m + bias[1] + 0.07 * rng.normal()))
    return f


@pytest.mark.parametrize(("wind", "sd_ratio"), [((0.0, 0.0), 0.5), ((1.5, -1.0), 0.75)])
def test_a_turn_of_the_heading_tells_the_accelerometers_bias_from_the_wind(wind, sd_ratio):
    # without the turn a bias of 0.07 m/s² reads as 0.27 m/s of wind, inside the σ the bias's prior gives;
    # a half turn learns it and the σ shrinks (in wind the drag's scale, unlearned in a hover, keeps a share)
    still = hover_with_bias(0.0, wind)
    turned = hover_with_bias(180.0, wind)
    err_still = math.hypot(still.wn_mps - wind[0], still.we_mps - wind[1])
    err_turned = math.hypot(turned.wn_mps - wind[0], turned.we_mps - wind[1])
    assert err_still > 0.15 and err_still < 2.45 * still.sd_mps
    assert err_turned < 0.1 and err_turned < 2.45 * turned.sd_mps
    assert turned.sd_mps < sd_ratio * still.sd_mps
    assert math.hypot(turned.bx_mps2 - 0.05, turned.by_mps2 + 0.05) < 0.02


def test_the_log_filter_holds_the_bias_and_covers_it_in_its_model_term():
    f = WindFilter(SIH[0], 1.0, bias_states=False)
    assert f.p[3][3] == f.p[4][4] == 0.0
    f.update(0.0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.05, 0.0))
    assert f.bx_mps2 == 0.0 and f.model_sd_mps == pytest.approx(0.05, rel=1e-6)  # 0.05 m/s² over a slope of 1 /s
