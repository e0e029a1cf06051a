"""Shared pytest fixtures, and the fuzz lane's selection."""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")

import pytest

from sitl_fakes.launcher import FakeVehicle


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
