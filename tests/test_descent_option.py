"""``flighttest fly --descent M``: start height and descent set the same way for every mission (issue 11
item 4). No flying: the command line is parsed and the mission planned (``build_request`` runs the
mission script's ``plan()`` with the profile), or refused with one line and exit code 2 before
anything connects. The helix is planned on a coarse grid (``n_intervals`` 20) to keep this fast."""

from __future__ import annotations

import json

import pytest

from flighttest.cli import build_parser, main
from flighttest.cli.fly import build_request
from flighttest.flying.mission_scripts import mission_config_path

URL = "udpin://0.0.0.0:14540"


def _request(argv: list[str]):
    return build_request(build_parser().parse_args(["fly", *argv, "--connect", URL]))


def _depth_m(req) -> float:
    """How far below its start the planned trajectory ends (NED d grows going down)."""
    return float(req.trajectory.df["d_m"].iloc[-1])


@pytest.fixture
def cli(capsys):
    def run(argv: list[str]) -> tuple[int, str, str]:
        capsys.readouterr()
        rc = main(argv)
        out, err = capsys.readouterr()
        return rc, out, err

    return run


def test_vertical_from_5_m_descends_3_m():
    req = _request(["vertical", "--vehicle", "x500", "--height", "5", "--descent", "3"])
    assert req.config.flight.start_height_m == 5.0 and req.config.plan["descent_m"] == 3.0
    assert _depth_m(req) == pytest.approx(3.0, abs=1e-6)
    req = _request(["vertical", "--vehicle", "x500", "--height", "7", "--descent", "5"])  # the campaign's
    assert _depth_m(req) == pytest.approx(5.0, abs=1e-6)


def test_helix_from_5_m_descends_3_m(tmp_path):
    text = mission_config_path("helix").read_text(encoding="utf-8")
    coarse = tmp_path / "helix_coarse.toml"
    coarse.write_text(text.replace("n_intervals = 60", "n_intervals = 20").replace("n_coarse = 30", "n_coarse = 10"))
    req = _request(["helix", "--vehicle", "x500", "--height", "5", "--descent", "3", "--config", str(coarse)])
    assert req.config.flight.start_height_m == 5.0 and req.config.plan["descent_m"] == 3.0
    assert req.trajectory.meta["kind"] == "helix"
    assert _depth_m(req) == pytest.approx(3.0, abs=0.1)  # the coarse grid's export ends within 0.1 m


def test_probe_descent_is_its_sweep_depth():
    req = _request(["probe", "--vehicle", "x500", "--descent", "2"])
    assert req.config.plan["amplitude_m"] == 2.0
    assert float(req.trajectory.df["d_m"].max()) == pytest.approx(2.0, abs=0.05)


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["vertical", "--height", "5", "--descent", "4.5"], "at most 4 m"),  # floor 1 m: 4 m of room
        (["helix", "--height", "5"], "descent of 5 m from 5 m"),  # the helix's own 5 m does not fit either
        (["probe", "--descent", "6.5"], "at most 6 m"),  # 8 m start, 2 m floor
        (["vertical", "--descent", "0"], "--descent must be"),
        (["vertical", "--descent", "nan"], "--descent must be a finite number"),
        (["vertical", "--descent", "-1"], "--descent must be"),
    ],
)
def test_a_descent_without_room_is_refused(cli, argv, needle):
    rc, out, err = cli(["fly", *argv, "--connect", URL, "--vehicle", "x500", "--json"])
    assert rc == 2 and needle in err and len(err.strip().splitlines()) == 1, err
    assert needle in json.loads(out)["error"]


def test_descent_is_refused_for_a_trajectory_file(cli, tmp_path):
    from flighttest.model.profiles import load_profile
    from flighttest.planner.export import vertical_trajectory
    from flighttest.planner.vertical import plan_vertical

    prof = load_profile("x500")
    path = tmp_path / "down"
    vertical_trajectory(plan_vertical(prof, height_m=2.0), "x500", prof.mass_kg).save(path)
    rc, _, err = cli(["fly", f"{path}.csv", "--connect", URL, "--vehicle", "x500", "--descent", "1"])
    assert rc == 2 and "--descent does not apply to a trajectory file" in err


def test_help_says_how_far_each_mission_goes(capsys):
    with pytest.raises(SystemExit):
        main(["fly", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--descent M" in text
    for words in ("probe 3 m (sweep depth)", "helix 5 m", "vertical 3 m", "helix 7 m", "vertical 5 m"):
        assert words in text, words
