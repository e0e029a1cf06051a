"""The plan cache (``flighttest.planner.plan_cache``): a plan is loaded only where everything it depends on is
the same — the whole profile, the question, flighttest's code and the mission script — and the helix mission's
own calm plan is made once."""

from __future__ import annotations

import dataclasses
import os
import shutil
import time
import tomllib

import pytest
import tomli_w

import flighttest.planner.helix as helix
from flighttest.errors import FlighttestError
from flighttest.flying.mission_scripts import MISSIONS, MISSIONS_DIR, load_mission_module
from flighttest.flying.missions_config import load_mission_config
from flighttest.model.profiles import load_profile
from flighttest.planner import plan_cache
from flighttest.planner.export import vertical_trajectory
from flighttest.planner.vertical import plan_vertical


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FLIGHTTEST_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "plans"


@pytest.fixture(scope="module")
def x500():
    return load_profile("x500")


# fields the key once left out (it hashed the profile's --json summary): each shapes a helix
SHAPING = {"max_rate_dps": (60.0, 60.0, 30.0), "inertia_kgm2": (0.05, 0.05, 0.09), "min_thrust_per_rotor_n": 1.0,
           "max_speed_mps": 4.0, "max_climb_mps": 1.0, "yaw_moment_per_thrust_m": 0.03}  # fmt: skip


@pytest.mark.parametrize("field", SHAPING)
def test_every_profile_field_that_shapes_a_plan_is_in_the_key(x500, field):
    assert getattr(x500, field) != SHAPING[field]
    other = dataclasses.replace(x500, **{field: SHAPING[field]})
    assert plan_cache.cache_key(other, {"q": 1}) != plan_cache.cache_key(x500, {"q": 1})


def test_where_the_profile_lies_and_what_it_says_of_itself_are_not(x500):
    copy = dataclasses.replace(x500, path="/elsewhere/x500.toml", description="the campaign's copy")
    assert plan_cache.cache_key(copy, {"q": 1}) == plan_cache.cache_key(x500, {"q": 1})
    assert plan_cache.cache_key(x500, {"q": 2}) != plan_cache.cache_key(x500, {"q": 1})


def _solver_in(path, text: str):
    path.write_text(text)
    scope: dict = {}
    exec(compile(text, str(path), "exec"), scope)  # a function whose source file is ``path``
    return scope["solve"]


def test_the_mission_script_that_asks_is_in_the_key_by_content(tmp_path, x500):
    text = "def solve():\n    return None\n"
    a = _solver_in(tmp_path / "a.py", text)
    same = _solver_in(tmp_path / "b.py", text)  # a copy elsewhere: the same plans
    edited = _solver_in(tmp_path / "c.py", text + "# the user's edit\n")
    key = plan_cache.cache_key(x500, {}, a)
    assert plan_cache.cache_key(x500, {}, same) == key
    assert plan_cache.cache_key(x500, {}, edited) != key
    assert plan_cache.cache_key(x500, {}, None) != key


def test_the_code_that_plans_is_in_the_key(tmp_path, x500):
    tree = tmp_path / "pkg"
    (tree / "planner").mkdir(parents=True)
    (tree / "planner" / "helix.py").write_text("RATE = 1\n")
    before = plan_cache.source_digest(tree)
    (tree / "planner" / "helix.py").write_text("RATE = 2\n")
    assert plan_cache.source_digest(tree) != before
    # flighttest's own tree is what the key hashes: this very module is in it
    assert plan_cache.code_fingerprint() != plan_cache.source_digest(tree)
    assert plan_cache.source_digest(plan_cache.PACKAGE_ROOT) in plan_cache.code_fingerprint()


class Counting:
    def __init__(self, profile, fail: bool = False):
        self.profile, self.fail, self.calls = profile, fail, 0

    def __call__(self):
        self.calls += 1
        if self.fail:
            raise FlighttestError("the planner did not converge (Infeasible_Problem_Detected)")
        return vertical_trajectory(plan_vertical(self.profile, height_m=2.0), self.profile.name, self.profile.mass_kg)


def test_a_plan_is_solved_once_and_a_failure_is_not_kept(cache, x500):
    solve = Counting(x500)
    first = plan_cache.cached_plan("t", x500, {"q": 1}, solve)
    again = plan_cache.cached_plan("t", x500, {"q": 1}, solve)
    assert solve.calls == 1 and again.duration_s == pytest.approx(first.duration_s)
    plan_cache.cached_plan("t", x500, {"q": 2}, solve)
    assert solve.calls == 2
    failing = Counting(x500, fail=True)
    for _ in range(2):
        with pytest.raises(FlighttestError, match="did not converge"):
            plan_cache.cached_plan("t", x500, {"q": 3}, failing)
    assert failing.calls == 2  # tried again at the next flight


def test_the_helix_missions_calm_plan_is_made_once_and_again_for_an_edited_script(cache, x500, tmp_path, monkeypatch):
    calls = []
    real = helix.solve_helix

    def counting(problem, **kw):
        calls.append(problem.height_m)
        return real(problem, **kw)

    monkeypatch.setattr(helix, "solve_helix", counting)  # the script imports it when it is loaded
    stem = MISSIONS["helix"]
    table = tomllib.loads((MISSIONS_DIR / f"{stem}.toml").read_text())
    table["plan"].update(n_intervals=24, n_coarse=12, descent_m=3.0)  # a small helix: seconds, not more
    user = tmp_path / "missions"
    user.mkdir()
    (user / f"{stem}.toml").write_text(tomli_w.dumps(table))
    shutil.copy(MISSIONS_DIR / f"{stem}.py", user)
    monkeypatch.setenv("FLIGHTTEST_MISSIONS", str(user))
    cfg = load_mission_config(user / f"{stem}.toml")
    first = load_mission_module("helix").plan(x500, cfg)
    again = load_mission_module("helix").plan(x500, cfg)
    assert len(calls) == 1 and again.duration_s == pytest.approx(first.duration_s, abs=1e-3)
    with (user / f"{stem}.py").open("a") as f:
        f.write("\n# the user's edit\n")
    load_mission_module("helix").plan(x500, cfg)
    assert len(calls) == 2


def test_files_unused_for_a_month_are_pruned_when_a_plan_is_kept_and_loading_one_keeps_it(cache, x500):
    solve = Counting(x500)
    plan_cache.cached_plan("t", x500, {"q": "flown every week"}, solve)
    cache.mkdir(parents=True, exist_ok=True)
    stale = [cache / f"helix-x500-{n}" for n in ("0ld.csv", "0ld.json", "0ld.failed", "0ld.lock", "0ld.timedout")]
    for path in stale:
        path.write_text("made by an older flighttest")
    month_ago = time.time() - (plan_cache.KEEP_UNUSED_DAYS + 1) * 86400
    for path in [*stale, *cache.glob("t-x500-*")]:
        os.utime(path, (month_ago, month_ago))
    plan_cache.cached_plan("t", x500, {"q": "flown every week"}, solve)  # loaded: used today
    assert solve.calls == 1 and all(p.exists() for p in stale)  # a load prunes nothing
    plan_cache.cached_plan("t", x500, {"q": "new"}, solve)  # a new plan kept: the unused go
    assert solve.calls == 2 and not any(p.exists() for p in stale)
    assert len(list(cache.glob("t-x500-*.csv"))) == 2  # the one loaded a moment ago stays, beside the new one
    assert plan_cache.prune(cache, now_s=time.time() + 31 * 86400) > 0  # a month on, both would go
