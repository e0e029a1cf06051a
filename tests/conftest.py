"""Shared pytest fixtures, and the fuzz lane's selection."""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")

import pytest

from sitl_fakes.launcher import FakeVehicle

# The vehicles the flight lane flies the helix with: their plans for the wind are made once per session
PLANNED_VEHICLES = ("x500", "arducopter_sitl")


@pytest.fixture
def fake_vehicle_factory(tmp_path):
    """``factory(vehicle="x500", **options) -> FakeVehicle`` (started, on a free port).

    Options map onto ``python -m sitl_fakes`` flags (``truth_onset=1.0``, ``wind_ned=(2, 0, 0)``,
    ``param={"MIS_TAKEOFF_ALT": 1.5}``, ...). The truth log goes to the test's tmp_path unless
    ``truth_log`` is given. Every fake started is stopped at teardown.
    """
    started: list[FakeVehicle] = []

    def factory(vehicle: str = "x500", **options) -> FakeVehicle:
        if "truth_log" not in options:
            options["truth_log"] = tmp_path / f"truth_{len(started)}.csv"
        fake = FakeVehicle(vehicle=vehicle, **options)
        started.append(fake)
        return fake.start()

    yield factory
    for fake in started:
        fake.stop()


@pytest.fixture(scope="session", autouse=True)
def plan_cache(tmp_path_factory, worker_id):
    """The plan cache (flighttest.planner.plan_cache) of this session, shared by its workers and inherited by
    the flights' processes (FLIGHTTEST_CACHE): never the user's own, which would hand the tests plans made
    before them."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if worker_id != "master" else base
    os.environ["FLIGHTTEST_CACHE"] = str(root / "flighttest-cache")
    return root / "flighttest-cache"


@pytest.fixture(scope="session")
def helix_plans_for_wind(plan_cache, worker_id):
    """The helix mission's plans for the wind (flighttest.planner.wind_plans), made before the first flight
    in the session's plan cache: a minute of IPOPT per vehicle, once, outside any flight's timeout. Odd
    workers take the vehicles in the other order, and each loads what the other planned (the cache's lock
    has it wait for a plan under way)."""
    from flighttest.flying.mission_scripts import load_mission_module, mission_config_path
    from flighttest.flying.missions_config import load_mission_config
    from flighttest.model.profiles import load_profile

    helix = load_mission_module("helix")
    cfg = load_mission_config(mission_config_path("helix"))
    odd = worker_id.removeprefix("gw").isdigit() and int(worker_id.removeprefix("gw")) % 2 == 1
    for name in reversed(PLANNED_VEHICLES) if odd else PLANNED_VEHICLES:
        helix.plans_for_wind(load_profile(name), cfg)


@pytest.fixture(autouse=True)
def _plans_before_flights(request):
    if request.node.get_closest_marker("flight") is not None:
        request.getfixturevalue("helix_plans_for_wind")


def pytest_collection_modifyitems(config, items):
    """The fuzz lane (``-m fuzz``, tests/test_fuzz_lane.py) runs only when asked for by a ``-m`` expression
    naming it: CI's ``-m 'not flight'`` and a bare ``pytest`` leave it out. Deselected, not skipped: a skip
    would report it as something that could not run."""
    if "fuzz" in (config.option.markexpr or ""):
        return
    kept = [item for item in items if item.get_closest_marker("fuzz") is None]
    if len(kept) < len(items):
        config.hook.pytest_deselected(items=[item for item in items if item.get_closest_marker("fuzz") is not None])
        items[:] = kept
