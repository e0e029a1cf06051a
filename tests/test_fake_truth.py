"""The fake's truth is an independent oracle: its blade-frame velocity comes from its own rotation
code (``sitl_fakes.disturbance.blade_velocity_mps``), checked here against flighttest's
(``flighttest.model.frames``) and against cases worked by hand."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from flighttest.model.frames import blade_velocity_mps as flighttest_blade
from flighttest.model.frames import quat_from_euler
from sitl_fakes.disturbance import blade_velocity_mps as fake_blade

speed = st.floats(-20.0, 20.0, allow_nan=False)
angle = st.floats(-math.pi, math.pi, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(speed, speed, speed, angle, st.floats(-1.5, 1.5), angle, speed, speed, speed)
def test_the_fakes_truth_agrees_with_flighttests_frames(vn, ve, vd, roll, pitch, yaw, wn, we, wd):
    q = [float(x) for x in quat_from_euler(roll, pitch, yaw)]
    w_fake, u_fake = fake_blade(vn, ve, vd, *q, wn, we, wd)
    w_ft, u_ft = flighttest_blade(vn, ve, vd, *q, wn, we, wd)
    assert np.isclose(w_fake, float(w_ft), atol=1e-9) and np.isclose(u_fake, float(u_ft), atol=1e-9)


def test_hand_worked_cases():
    level = (1.0, 0.0, 0.0, 0.0)
    # level, sinking at 2 m/s: the air comes up through the disk, w = +2
    assert fake_blade(0.0, 0.0, 2.0, *level) == (2.0, 0.0)
    # level, flying north at 3 m/s into a 1 m/s north wind: 2 m/s in the disk's plane
    assert fake_blade(3.0, 0.0, 0.0, *level, 1.0, 0.0, 0.0) == (0.0, 2.0)
    # pitched nose-down 30° (FRD pitch −30°) flying north at 4 m/s, as in forward flight: part of the
    # air flows down through the disk, w = −4 sin 30°, the rest across it
    c, s = math.cos(math.radians(-15.0)), math.sin(math.radians(-15.0))
    w, u = fake_blade(4.0, 0.0, 0.0, c, 0.0, s, 0.0)
    assert math.isclose(w, -4.0 * math.sin(math.radians(30.0)), abs_tol=1e-12)
    assert math.isclose(u, 4.0 * math.cos(math.radians(30.0)), abs_tol=1e-12)
