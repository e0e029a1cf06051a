"""Plots a reader can trust (issue 25): the guard region shaded on its forbidden side only, yaw unwrapped,
axes fitted to the data with the region in view, one colour per quantity, start and end marked, the plan
under what was flown; and what the plan commands and `vehicle list` show.

No flying: plans from the closed-form planners, flights from synthetic logs in a flighttest folder.
"""

from __future__ import annotations

import argparse
import io
import json
import math
import shutil
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
from rich.console import Console

from flighttest.analysis import report
from flighttest.analysis.pipeline import analyse_path
from flighttest.analysis.planned import planned_path
from flighttest.cli import main
from flighttest.flying.mission_scripts import MISSIONS_DIR, load_mission_module, mission_config_path
from flighttest.flying.missions_config import load_mission_config
from flighttest.model.aero import guard_bound_mps
from flighttest.model.chart import END_STYLE, START_STYLE, VD_COLOUR, W_COLOUR, guard_boundary_n
from flighttest.model.profiles import load_profile
from flighttest.planner.export import vertical_trajectory
from flighttest.planner.plot import trajectory_figure
from flighttest.planner.problems import vehicle_constraint, vertical_constraint, vertical_plan
from synthetic import UNIX0, SyntheticFlight, write_tlog


@pytest.fixture(scope="module")
def x500():
    return load_profile("x500")


def _axes(fig) -> dict[str, plt.Axes]:
    return {ax.get_title(): ax for ax in fig.axes if ax.get_title()}


def _ends(ax) -> tuple[list, list]:
    """The start rings and end squares drawn on ``ax``."""
    lines = ax.get_lines()
    rings = [ln for ln in lines if ln.get_marker() == START_STYLE["marker"] and ln.get_linestyle() == "None"]
    squares = [ln for ln in lines if ln.get_marker() == END_STYLE["marker"]]
    return rings, squares


def _shade_floor(ax) -> np.ndarray:
    """The lower edge of the (single) shaded region on ``ax``: its polygon's vertices, bottom side."""
    (poly,) = [c for c in ax.collections if type(c).__name__ in ("PolyCollection", "FillBetweenPolyCollection")]
    v = poly.get_paths()[0].vertices
    return v


# -- the plan plot --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def vertical(x500):
    plan = vertical_plan(x500, 3.0, extra_margin_mps=0.35, accel_fraction=0.15)
    return vertical_trajectory(plan, "x500", x500.mass_kg), vertical_constraint(x500, plan)


def test_the_plan_plot_shades_the_guard_region_not_the_plans_own_bound(vertical, x500):
    traj, constraint = vertical
    guard = vehicle_constraint(x500, "guard")
    fig = trajectory_figure(traj, constraint, guard=guard)
    try:
        ax = _axes(fig)["w against the guard region (its boundary at the plan's u)"]
        bound = x500.w_allow_mps - x500.vrs.margin_mps  # straight down: the flat part of the guard boundary
        plan_bound = constraint.w_allow_mps - constraint.margin_mps
        assert plan_bound < bound - 0.3  # the plan keeps 0.35 m/s inside: the two are far apart
        floor = _shade_floor(ax)[:, 1]
        assert floor.min() == pytest.approx(bound, abs=1e-9)  # nothing shaded below the guard's boundary
        w = next(ln for ln in ax.get_lines() if ln.get_label().startswith("w:")).get_ydata()
        lo, hi = ax.get_ylim()
        assert lo <= w.min() and hi > bound + 0.2 * (hi - lo)  # the plan and a band of the region in view
        # the velocity-space panel: the same boundary over u, shaded above, the axis from just left of 0
        vs = _axes(fig)["blade-frame velocity space"]
        verts = _shade_floor(vs)
        u_edge = verts[:, 0]
        shaded_bottom = np.interp(np.linspace(0, u_edge.max(), 50), *_lower(verts))
        expected = guard_bound_mps(np.linspace(0, u_edge.max(), 50), x500.w_allow_mps, 20.0, x500.vrs.margin_mps)
        np.testing.assert_allclose(shaded_bottom, expected, atol=1e-6)
        assert -0.1 < vs.get_xlim()[0] < 0 and vs.get_xlim()[1] >= 1.0
    finally:
        plt.close(fig)


def _lower(verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) of a fill_between polygon's lower edge: its first half, from left to right."""
    n = len(verts) // 2
    x, y = verts[1:n, 0], verts[1:n, 1]
    order = np.argsort(x)
    return x[order], y[order]


def test_the_plan_plot_unwraps_yaw_and_marks_the_ends_in_distinct_colours(vertical, x500):
    traj, constraint = vertical
    spin = traj.df.copy()
    # a yaw turning at 120°/s: wrapped into ±180° it would jump across the panel every 3 s
    spin["yaw_deg"] = (spin["t_s"] * 120.0 + 180.0) % 360.0 - 180.0
    turned = type(traj)(df=spin, meta=dict(traj.meta))
    fig = trajectory_figure(turned, constraint, guard=vehicle_constraint(x500, "guard"))
    try:
        panels = _axes(fig)
        yaw = next(ln for ln in panels["attitude"].get_lines() if ln.get_label() == "yaw").get_ydata()
        assert np.abs(np.diff(yaw)).max() < 5.0 and np.ptp(yaw) > 360.0
        # start and end: on the first and the last point of the path and of the height
        for title in ("path, seen from the side", "height"):
            rings, squares = _ends(panels[title])
            line = panels[title].get_lines()[0]
            assert rings[0].get_ydata()[0] == pytest.approx(line.get_ydata()[0])
            assert squares[0].get_ydata()[0] == pytest.approx(line.get_ydata()[-1])
        vd = next(ln for ln in panels["speeds"].get_lines() if ln.get_label().startswith("v_D"))
        w = next(ln for ln in panels["w against the guard region (its boundary at the plan's u)"].get_lines()
                 if ln.get_label().startswith("w:"))  # fmt: skip
        assert vd.get_color() == VD_COLOUR and w.get_color() == W_COLOUR and VD_COLOUR != W_COLOUR
    finally:
        plt.close(fig)


# -- the flight plots -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def folder(tmp_path_factory, x500):
    """A flighttest log folder: a synthetic 5 m descent at t = 10 s, the plan it streamed, its events."""
    d = tmp_path_factory.mktemp("flight") / "20261201-120000-vertical"
    d.mkdir()
    flight = SyntheticFlight(duration_s=30.0, descents=[(10.0, 5.0, 8.0)], yaw_deg=0.0)
    write_tlog(flight, d / "flight.tlog", rate_hz=25.0)
    plan = vertical_trajectory(vertical_plan(x500, 5.0, extra_margin_mps=0.35, accel_fraction=0.15), "x500",
                               x500.mass_kg)  # fmt: skip
    plan.save(d / "trajectory.csv")
    origin = [0.0, 0.0, -flight.start_alt_m]
    events = [{"t_s": 10.0, "unix_s": UNIX0 + 10.0, "event": "stream_start", "origin_ned": origin, "rows": 10,
               "end_ned": [0.0, 0.0, origin[2] + 5.0]}]  # fmt: skip
    (d / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events))
    meta = {"mission": "vertical", "start_unix_s": UNIX0, "vehicle": {"name": "x500"}}
    (d / "meta.json").write_text(json.dumps(meta))
    return d


@pytest.fixture
def kept(monkeypatch) -> list:
    """The figures the report module draws, kept open to be read (it closes each after saving)."""
    figs: list = []
    close = plt.close
    monkeypatch.setattr(report.plt, "close", lambda fig=None: figs.append(fig))
    yield figs
    for fig in figs:
        close(fig)


def test_the_plan_is_placed_where_the_flight_streamed_it(folder):
    a = analyse_path(folder, vehicle="x500")
    plan = planned_path(a.log)
    t0 = next(e["t_s"] for e in a.log.events if e["event"] == "stream_start")
    assert plan["t_s"].iloc[0] == pytest.approx(t0) and plan["d_m"].iloc[0] == pytest.approx(-10.0)
    assert plan["d_m"].iloc[-1] == pytest.approx(-5.0) and (plan[["n_m", "e_m"]] == 0.0).all().all()
    assert plan["w_mps"].max() == pytest.approx(plan["vd_mps"].max())  # level, still air: w is the descent rate
    # a log that does not say what was planned has no plan, and no error
    (folder.parent / "bare").mkdir(exist_ok=True)
    shutil.copy(folder / "flight.tlog", folder.parent / "bare" / "flight.tlog")
    assert planned_path(analyse_path(folder.parent / "bare", vehicle="x500").log) is None


def test_the_path_plot_draws_the_plan_under_the_flight_and_marks_its_ends(folder, tmp_path, kept):
    a = analyse_path(folder, vehicle="x500")
    report.plot_path(a, tmp_path / "path.png")
    assert (tmp_path / "path.png").stat().st_size > 10_000
    above = _axes(kept[0])["seen from above"]
    labels = [ln.get_label() for ln in above.get_lines()]
    assert labels.index("the plan (straight down)") < labels.index("flown")  # under it
    rings, squares = _ends(above)
    s = a.log.state
    assert rings[0].get_xdata()[0] == pytest.approx(s["e_m"].iloc[0])
    assert squares[0].get_ydata()[0] == pytest.approx(s["n_m"].iloc[-1])


def test_the_velocity_space_plot_is_fitted_to_a_vertical_flight(folder, tmp_path, kept, x500):
    a = analyse_path(folder, vehicle="x500")
    report.plot_velocity_space(a, tmp_path / "vs.png")
    ax = kept[0].axes[0]
    (x_lo, x_hi), (y_lo, y_hi) = ax.get_xlim(), ax.get_ylim()
    # not ±2 v_h with a dot column at 0: the flight's own speeds, 0.1 v_h wide at least
    assert a.track["v_H_n"].max() < 0.05 and x_hi == pytest.approx(0.108) and -0.01 < x_lo < 0
    assert y_lo <= a.track["v_z_n"].min() and a.track["v_z_n"].max() <= y_hi
    assert y_lo < float(guard_boundary_n(x500, x_hi))  # the guard boundary and its forbidden side in view
    rings, squares = _ends(ax)
    assert len(rings) == len(squares) == len(a.descents) >= 1
    assert any(ln.get_label() == "the plan (still air)" for ln in ax.get_lines())


def test_the_altitude_plot_tells_the_descent_rate_from_w(folder, tmp_path, kept):
    a = analyse_path(folder, vehicle="x500")
    report.plot_altitude(a, tmp_path / "alt.png")
    height, rates = kept[0].axes[:2]
    by_label = {ln.get_label(): ln for ln in rates.get_lines()}
    vd = by_label["descent rate vd (over the ground)"]
    w = by_label["w through the disk (air-relative)"]
    assert vd.get_color() == VD_COLOUR and w.get_color() == W_COLOUR and vd.get_linewidth() > w.get_linewidth()
    assert "planned descent rate" in by_label and any(ln.get_label() == "the plan" for ln in height.get_lines())
    # the region in view above the boundary, and shaded only above it
    bound = by_label[next(k for k in by_label if k.startswith("guard boundary"))].get_ydata()
    assert rates.get_ylim()[1] > np.nanmax(bound) and _shade_floor(rates)[:, 1].min() >= np.nanmin(bound) - 1e-9


# -- what `plan` plans -------------------------------------------------------------------------------


class _Stop(Exception):
    pass


def _problem_of(monkeypatch, run) -> object:
    """The helix problem ``run()`` hands the solver (stopped there: nothing is solved)."""
    import flighttest.planner.helix as helix

    seen = []

    def capture(problem, verbose=False):
        seen.append(problem)
        raise _Stop

    monkeypatch.setattr(helix, "solve_helix", capture)
    with pytest.raises(_Stop):
        run()
    return seen[0]


def _plan_args(**kw) -> argparse.Namespace:
    base = {"vehicle": "x500", "paper": False, "height": None, "radius": None, "intervals": None, "end": None,
            "tilt_max": None, "rate_max": None, "thrust_fraction": None, "wind": None, "constraint": None,
            "margin": None, "output": None, "json": True, "plot": None, "verbose": False}  # fmt: skip
    return argparse.Namespace(**{**base, **kw})


def test_plan_helix_plans_what_fly_helix_flies_and_paper_the_papers_problem(monkeypatch, tmp_path, x500):
    from flighttest.cli.plan import cmd_helix

    monkeypatch.chdir(tmp_path)
    # a plan cache of its own: the mission's plan, made by another test, would be loaded and nothing solved
    monkeypatch.setenv("FLIGHTTEST_CACHE", str(tmp_path / "cache"))
    cfg = load_mission_config(mission_config_path("helix"))
    flown = _problem_of(monkeypatch, lambda: load_mission_module("helix").plan(x500, cfg))
    planned = _problem_of(monkeypatch, lambda: cmd_helix(_plan_args()))
    assert planned.summary() == flown.summary()
    paper = _problem_of(monkeypatch, lambda: cmd_helix(_plan_args(paper=True)))
    assert paper.constraint.w_allow_mps == 0.0  # the pure cone
    assert math.degrees(paper.tilt_max_rad) == pytest.approx(x500.max_tilt_deg)  # full tilt
    assert math.degrees(paper.rate_max_rps[0]) == pytest.approx(x500.max_rate_dps[0])  # and body rates
    assert math.degrees(flown.tilt_max_rad) < x500.max_tilt_deg - 5 and flown.constraint.w_allow_mps > 0
    assert (paper.height_m, paper.radius_m) == (flown.height_m, flown.radius_m)  # the same descent


def test_plan_helix_says_in_its_file_which_problem_it_solved(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["plan", "helix", "--intervals", "30", "--json", "-o", "h"]) == 0
    out = json.loads(capsys.readouterr().out)
    meta = json.loads((tmp_path / "h.json").read_text())
    assert out["plan_basis"] == meta["plan_basis"] == "mission"
    assert meta["mission_config"] == str(MISSIONS_DIR / "helix_descent.toml")
    assert meta["tracking_margin"]["guard_margin_mps"] == 0.4


def test_plan_vertical_and_probe_follow_the_users_copy_of_the_mission(tmp_path, capsys, monkeypatch, x500):
    mine = tmp_path / "missions"
    mine.mkdir()
    for stem, edits in (("vertical_descent", {"descent_m": "2.5", "extra_margin_mps": "0.2"}),
                        ("vrs_probe", {"amplitude_m": "2.0"})):  # fmt: skip
        shutil.copy(MISSIONS_DIR / f"{stem}.py", mine)
        text = (MISSIONS_DIR / f"{stem}.toml").read_text()
        for key, value in edits.items():
            text = "\n".join(f"{key} = {value}" if ln.startswith(f"{key} ") else ln for ln in text.splitlines())
        (mine / f"{stem}.toml").write_text(text + "\n")
    monkeypatch.setenv("FLIGHTTEST_MISSIONS", str(mine))
    monkeypatch.chdir(tmp_path)
    assert main(["plan", "vertical", "--json", "-o", "v"]) == 0
    v = json.loads(capsys.readouterr().out)
    assert v["mission_config"] == str(mine / "vertical_descent.toml") and v["plan_basis"] == "mission"
    assert v["problem"]["height_m"] == 2.5
    assert v["problem"]["margin_mps"] == pytest.approx(x500.vrs.margin_mps + 0.2)
    assert main(["plan", "probe", "--json", "-o", "p"]) == 0
    p = json.loads(capsys.readouterr().out)
    assert p["problem"]["amplitude_m"] == 2.0 and p["mission_config"] == str(mine / "vrs_probe.toml")
    # an option still wins over the mission's value
    assert main(["plan", "vertical", "--json", "--height", "4", "-o", "v4"]) == 0
    assert json.loads(capsys.readouterr().out)["problem"]["height_m"] == 4.0


# -- vehicle list -------------------------------------------------------------------------------------


def test_vehicle_list_fits_80_columns_uncut(tmp_path, monkeypatch):
    from flighttest.cli import vehicle

    mine = tmp_path / "vehicles"
    mine.mkdir()
    long_name = "x" * vehicle.NAME_FITS_80
    text = Path(load_profile("x500").path).read_text(encoding="utf-8")
    (mine / f"{long_name}.toml").write_text(text.replace('name = "x500"', f'name = "{long_name}"'))
    monkeypatch.setenv("FLIGHTTEST_VEHICLES", str(mine))
    out = io.StringIO()
    monkeypatch.setattr(vehicle, "console", Console(file=out, width=80, color_system=None))
    assert vehicle.cmd_list(argparse.Namespace(json=False)) == 0
    text = out.getvalue()
    assert "…" not in text and max(len(line) for line in text.splitlines()) <= 80
    for name in (long_name, "arducopter_sitl", "mambo", "sih_quadx", "x500"):
        assert f" {name} " in text
    for header in ("mass", "kg", "rotor Ø", "v_h", "w_allow", "m/s", "/ v_h", "cone"):
        assert header in text
