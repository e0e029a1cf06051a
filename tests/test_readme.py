"""The README runs as written: every ```bash and ```python block of README.md is run here against the
fake, or says why not.

Each block is preceded by a marker, an HTML comment the rendered README does not show:

- ``<!-- readme-test: setup ... -->``: the two set-up commands at the top; CI runs them itself
  (``.ci/run``), so they are only checked to be what CI runs;
- ``<!-- readme-test: hardware ... -->``: needs a real vehicle (or PX4 SITL); not run;
- ``<!-- readme-test: fake ... -->``: starts the fake in a terminal of its own; the test starts it on a
  free port instead of the README's, and puts that port wherever the README has its own;
- ``<!-- readme-test: run -->``: run with bash (``set -e``), or this Python, in an empty folder, against
  that fake.

A block without a marker fails the fast test below: no command in the README goes untested unnoticed.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest
import tomli_w

from flighttest.flying.mission_scripts import MISSIONS, shipped_dir
from flighttest.flying.params_file import read_params
from test_fly_missions import CI_STALE_PERIODS

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
KINDS = ("setup", "hardware", "fake", "run")
MARKER = re.compile(r"<!--\s*readme-test:\s*(\w+)[^>]*-->")
FENCE = re.compile(r"^```(bash|python)\n(.*?)^```$", re.S | re.M)


def readme_blocks(text: str | None = None) -> list[tuple[str | None, str, str]]:
    """(marker kind or None, language, block text) of every ```bash and ```python block, in order."""
    text = README.read_text(encoding="utf-8") if text is None else text
    out = []
    for m in FENCE.finditer(text):
        before = text[: m.start()].rstrip().splitlines()
        marker = MARKER.fullmatch(before[-1].strip()) if before else None
        out.append((marker.group(1) if marker else None, m.group(1), m.group(2)))
    return out


def blocks_of(kind: str, lang: str | None = None) -> list[str]:
    return [block for k, lg, block in readme_blocks() if k == kind and lang in (None, lg)]


def run_blocks() -> list[tuple[str, str]]:
    """(language, text) of the blocks the flight test runs."""
    return [(lg, block) for k, lg, block in readme_blocks() if k == "run"]


def fake_port_of(block: str) -> str:
    """The port the README's fake listens on (``--port P``): the commands connect to it."""
    m = re.search(r"--port\s+(\d+)", block)
    assert m, f"the fake's block names no --port: {block!r}"
    return m.group(1)


# -- fast: the markers and what they promise ----------------------------------------------------------


def test_every_block_is_marked():
    blocks = readme_blocks()
    assert len(blocks) >= 5
    unmarked = [b.splitlines()[0] for k, _, b in blocks if k not in KINDS]
    assert not unmarked, f"README blocks without a readme-test marker of {KINDS}: {unmarked}"
    assert len(blocks_of("fake")) == 1 and len(blocks_of("run")) >= 2 and len(blocks_of("setup")) == 2


def test_the_setup_blocks_are_what_ci_runs():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    campaign, tests = (b.strip() for b in blocks_of("setup"))
    assert tests in ci  # the test command, as it is
    assert "campaign --sim --yes -o" in campaign and '"$ft" campaign --sim --yes -o' in ci  # the release check


def test_the_run_blocks_use_the_fake_and_the_hardware_blocks_do_not():
    port = fake_port_of(blocks_of("fake")[0])
    for block in blocks_of("run"):
        urls = re.findall(r"--connect\s+(\S+)", block) + re.findall(r"connect=\"([^\"]+)\"", block)
        assert urls and set(urls) == {f"udpout://127.0.0.1:{port}"}, block
        assert "<" not in block, f"a placeholder in a block that runs: {block!r}"
    for block in blocks_of("hardware"):
        assert port not in block and "--sim" not in block


# -- flight: run them ---------------------------------------------------------------------------------


@pytest.fixture
def readme_fake(tmp_path):
    """The README's fake, started as its block says but on a free port; (its port, the README's port)."""
    block = blocks_of("fake")[0]
    readme_port = fake_port_of(block)
    folder = tmp_path / "fake"
    folder.mkdir()
    proc = subprocess.Popen(
        ["bash", "-c", "exec " + re.sub(r"--port\s+\d+", "--port 0", block.strip())], cwd=folder, env=_env(tmp_path),
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, start_new_session=True,
    )  # fmt: skip
    try:
        first = proc.stdout.readline()
        m = re.match(r"connect: udpout://127\.0\.0\.1:(\d+)", first)
        assert m, f"the fake did not start: {first!r}"
        yield m.group(1), readme_port
    finally:
        os.killpg(proc.pid, signal.SIGINT)  # as the README says: Ctrl-C stops it
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert (folder / "truth.csv").stat().st_size > 0  # the truth log the block asks for


def _env(tmp_path: Path) -> dict[str, str]:
    """This checkout's flighttest first on PATH, a home of its own (nothing of the user's profiles or
    missions, nothing written into theirs), matplotlib's cache where it was."""
    import matplotlib

    env = dict(os.environ)
    env.pop("FLIGHTTEST_VEHICLES", None)
    env.pop("FLIGHTTEST_MISSIONS", None)
    env.pop("FLIGHTTEST_LOG_DIR", None)
    home = tmp_path / "home"
    home.mkdir(exist_ok=True)
    env.update(HOME=str(home), MPLCONFIGDIR=matplotlib.get_configdir(), COLUMNS="100",
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}")  # fmt: skip
    return env


def _ci_missions(tmp_path: Path) -> Path:
    """The shipped missions in a user folder (FLIGHTTEST_MISSIONS), each with the CI stale-telemetry
    allowance: the field's 0.25 s rule aborted a README flight on a busy 2-core box (257 ms without
    telemetry, 2026-12-07). What the blocks type stays as the README shows it."""
    folder = tmp_path / "ci-missions"
    folder.mkdir()
    for name in MISSIONS.values():
        shutil.copy(shipped_dir() / f"{name}.py", folder)
        cfg = tomllib.loads((shipped_dir() / f"{name}.toml").read_text(encoding="utf-8"))
        cfg["guard"]["stale_periods"] = CI_STALE_PERIODS
        (folder / f"{name}.toml").write_text(tomli_w.dumps(cfg), encoding="utf-8")
    return folder


@pytest.mark.flight
@pytest.mark.timeout(900)
@pytest.mark.parametrize("index", range(len(run_blocks())), ids=lambda i: f"run-block-{i + 1}")
def test_the_readme_block_runs_against_the_fake(index, readme_fake, tmp_path):
    port, readme_port = readme_fake
    lang, block = run_blocks()[index]
    block = re.sub(rf"\b{readme_port}\b", port, block)
    work = tmp_path / "work"
    work.mkdir()
    t0 = time.monotonic()
    argv = [sys.executable, "-c", block] if lang == "python" else ["bash", "-e", "-o", "pipefail", "-c", block]
    env = {**_env(tmp_path), "FLIGHTTEST_MISSIONS": str(_ci_missions(tmp_path))}
    proc = subprocess.run(argv, cwd=work, env=env, capture_output=True, text=True, timeout=840)
    assert proc.returncode == 0, f"exit {proc.returncode} after {time.monotonic() - t0:.0f} s\n{block}\n" + (
        proc.stdout[-4000:] + proc.stderr[-4000:]
    )
    assert "Traceback" not in proc.stderr
    home = tmp_path / "home"
    assert not (home / ".config" / "flighttest" / "vehicles").exists()  # the user's profiles untouched
    if lang == "python":  # one flight: its outcome printed, its folder under logs/
        assert proc.stdout.strip().splitlines()[-1].split()[0] == "completed", proc.stdout  # the block's print
        (flight,) = (work / "logs").iterdir()
        assert flight.name.split("-")[-1] == "helix"
        events = [json.loads(line) for line in (flight / "events.jsonl").read_text().splitlines() if line.strip()]
        rule = next(e for e in events if e["event"] == "stale_rule")
        assert rule["offboard_s"] > 0.25, rule  # the CI allowance (_ci_missions) reached the flight
    elif "flighttest params" in block:  # saved, one change applied, the saved value restored
        assert read_params(work / "before.params")["MPC_Z_VEL_MAX_DN"] == 1.5
        assert proc.stdout.count("set 1 of 1") == 2, proc.stdout  # apply 1.2, restore 1.5
    elif "campaign" in block:
        (out,) = [Path(m) for m in re.findall(r"-o\s+(\S+)", block)]
        assert (work / out / "report" / "summary.md").is_file()
        assert (work / out / "report" / "velocity_space.png").stat().st_size > 10_000
    else:  # the steps by hand: what each one writes
        here = work / "rehearsal"
        # the onset stored, or none found, or one refused (the estimate's error: README, "Each step by hand")
        assert (here / "vehicles" / "x500.toml").is_file() or "no onset up to" in proc.stdout or \
            "is not a plausible VRS onset" in proc.stderr  # fmt: skip
        for png in ("vertical.png", "helix.png"):
            assert (here / png).stat().st_size > 10_000
        assert (here / "report" / "report.md").is_file()
        flights = sorted(p.name.split("-")[-1] for p in (here / "logs").iterdir() if p.is_dir())
        assert flights == ["helix", "probe", "vertical"]
        assert proc.stdout.count("completed") >= 2  # fly vertical and fly helix
