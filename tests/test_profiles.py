"""Vehicle profiles: shipped ones load, bad ones fail with one line naming file and field."""

import math
from pathlib import Path

import pytest

from flighttest.errors import FlighttestError
from flighttest.model import aero
from flighttest.model.profiles import list_profiles, load_profile, write_w_allow

GOOD = """
name = "test_quad"
mass_kg = 1.0
n_rotors = 4
rotor_diameter_m = 0.2
arm_length_m = 0.2
inertia_kgm2 = [0.01, 0.01, 0.02]
max_thrust_per_rotor_n = 6.0
max_rate_dps = [200.0, 200.0, 150.0]
max_tilt_deg = 35.0
[vrs]
cone_deg = 20.0
"""


@pytest.fixture
def user_dir(tmp_path, monkeypatch):
    d = tmp_path / "vehicles"
    d.mkdir()
    monkeypatch.setenv("FLIGHTTEST_VEHICLES", str(d))
    return d


def test_shipped_profiles():
    names = {p.name for p in list_profiles()}
    assert {"mambo", "tunnel_rig", "x500"} <= names
    mambo = load_profile("mambo")
    assert mambo.mass_kg == 0.063 and mambo.rotor_diameter_m == 0.065
    # v_h from the profile's own numbers, not the paper's quoted 1.54 m/s
    t = 0.063 * aero.G_MPS2 / 4
    assert mambo.v_h_mps == pytest.approx(math.sqrt(t / (2 * 1.225 * math.pi * 0.0325**2)))
    # default w_allow: Onera's boundary at v_H = 0, which for the Mambo is the paper's observed 0.6 m/s
    assert mambo.w_allow_mps == pytest.approx(0.1348 * mambo.v_h_mps, rel=1e-3)
    assert mambo.w_allow_mps == pytest.approx(0.6, abs=0.02)


def test_user_profile_shadows_and_w_allow_written(user_dir):
    (user_dir / "test_quad.toml").write_text(GOOD)
    p = load_profile("test_quad")
    assert p.vrs.w_allow_mps is None
    out = write_w_allow(p, 0.42, "probe flight 2026-11-22 (test)")
    assert out == user_dir / "test_quad.toml"
    again = load_profile("test_quad")
    assert again.w_allow_mps == 0.42 and "probe flight" in again.w_allow_source


def test_write_w_allow_of_shipped_profile_goes_to_user_dir(user_dir):
    out = write_w_allow(load_profile("x500"), 0.5, "probe")
    assert out.parent == user_dir
    assert load_profile("x500").w_allow_mps == 0.5


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda s: s.replace("mass_kg = 1.0\n", ""), "mass_kg"),
        (lambda s: s.replace("mass_kg = 1.0", 'mass_kg = "heavy"'), "mass_kg"),
        (lambda s: s.replace("mass_kg = 1.0", "mass_kg = -1.0"), "mass_kg"),
        (lambda s: s.replace("mass_kg = 1.0", "mass_kg = nan"), "mass_kg"),
        (lambda s: s.replace("n_rotors = 4", "n_rotors = 4.5"), "n_rotors"),
        (lambda s: s.replace("[0.01, 0.01, 0.02]", "[0.01, 0.01]"), "inertia_kgm2"),
        (lambda s: s.replace("cone_deg = 20.0", "cone_deg = 95.0"), "vrs.cone_deg"),
        (lambda s: "colour = 'red'\n" + s, "colour"),
        (lambda s: s + "margin_mps = -0.1\n", "vrs.margin_mps"),
        (lambda s: s.replace("max_thrust_per_rotor_n = 6.0", "max_thrust_per_rotor_n = 1.0"), "max_thrust_per_rotor_n"),
    ],
)
def test_bad_profile_names_file_and_field(tmp_path, edit, field):
    f = tmp_path / "bad.toml"
    f.write_text(edit(GOOD))
    with pytest.raises(FlighttestError) as exc:
        load_profile(str(f))
    msg = str(exc.value)
    assert str(f) in msg and f"'{field}'" in msg and "\n" not in msg


def test_malformed_toml_and_unknown_name(tmp_path):
    f = tmp_path / "broken.toml"
    f.write_text("name = [unclosed\n")
    with pytest.raises(FlighttestError, match="malformed TOML"):
        load_profile(str(f))
    with pytest.raises(FlighttestError, match="unknown vehicle 'nope'"):
        load_profile("nope")


def test_arducopter_sitl_profile_is_sitls_default_quad():
    p = load_profile("arducopter_sitl")
    # SIM_Frame's default model: 3.0 kg, 0.35 m motor-to-motor, disc area 0.385 m² for four 0.35 m rotors
    assert (p.mass_kg, p.n_rotors, p.arm_length_m * 2) == (3.0, 4, 0.35)
    assert 4 * math.pi * (p.rotor_diameter_m / 2) ** 2 == pytest.approx(0.385, rel=0.01)
    # SITL's inertia when none is given: m/4 (d/2)², m/2 (d/2)²
    assert p.inertia_kgm2[0] == pytest.approx(3.0 * 0.25 * 0.175**2, rel=1e-3)
    assert p.inertia_kgm2[2] == pytest.approx(3.0 * 0.5 * 0.175**2, rel=1e-3)
    # hover at MOT_THST_HOVER 0.39 of full thrust; ATC_ANGLE_MAX 30°, WP_SPD_UP 2.5 m/s
    assert 1.0 / p.thrust_to_weight == pytest.approx(0.39, abs=0.002)
    assert (p.max_tilt_deg, p.max_climb_mps) == (30.0, 2.5)
    assert Path(p.path).read_text().count("ASSUMPTION") >= 4  # what SITL has no figure for says so
