"""The fuzz lane (issue 23): seeded random inputs for a fixed time, every command's contract checked on each.

    FLIGHTTEST_FUZZ_S=300 .venv/bin/python -m pytest -m fuzz -n 2 -q -rP   # the nightly run (default 20 s)
    FLIGHTTEST_FUZZ_SEED=7 ...                                             # another sequence (default 23)
    FLIGHTTEST_FUZZ_TRY=plan:41 ...                                        # replay try 41 of the plan lane alone

Left out of every other run: tests/conftest.py deselects the ``fuzz`` marker unless a ``-m`` expression
names it. The time is shared by four lanes (``LANES``), one test each:

- ``logs``: the real log slices in tests/data and small synthetic logs (a probe among them, alone and in a
  flighttest log folder), mutated — bytes flipped, overwritten, inserted, cut, duplicated; a tlog's record
  timestamps rewritten; its messages re-packed with a valid checksum around extreme values (inf, NaN, 1e30,
  the integer limits); records dropped, repeated, swapped — then ``identify``, ``analyse``, ``compare`` or
  ``report`` on them;
- ``plan``: option values for ``plan vertical|probe|helix|planar`` — numbers at, near and beyond their ranges,
  near-zero ones, non-numbers — and profiles with one number replaced;
- ``inputs``: ``identify`` / ``analyse`` / ``compare`` / ``report`` options and paths (empty, too long,
  a newline, a FIFO, a folder where a file goes, a file where a folder goes, a symlink loop), the user
  profile folder ``identify --write-profile`` writes to, folders to walk with such names inside;
- ``campaign``: its options, ``-o`` folders and damaged ``campaign.json`` records — never ``--yes``: without
  a terminal a campaign that would start is refused, so nothing flies.

Try ``k`` of a lane draws from its own generator, seeded with (seed, lane, k): any try replays alone.
Each runs ``flighttest.cli.main`` in-process in a fresh folder, and the contract (``check``) is: no exception
out of ``main`` (a traceback) and no line of a catch-all (``CATCH_ALL``: an exception nobody expected); within
its time limit (a hang) and under a memory cap (an allocation of gigabytes); no warning on the way; an exit
code the command has (0 or 2; 1 only for a plan whose solver did not converge); with exit 2 one
``flighttest: error:`` line (``analyse``/``compare``/``report``: one per log) and, but for ``analyse``
(whose other logs are analysed), nothing written; every line on stderr a ``flighttest:`` line; with
``--json`` one JSON document on stdout.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import random
import re
import resource
import shutil
import signal
import struct
import time
import traceback
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as dialect

from flighttest.cli import main
from flighttest.model.profiles import SHIPPED_DIR

pytestmark = pytest.mark.fuzz

FUZZ_S = float(os.environ.get("FLIGHTTEST_FUZZ_S", "20"))
SEED = int(os.environ.get("FLIGHTTEST_FUZZ_SEED", "23"))
ONLY = os.environ.get("FLIGHTTEST_FUZZ_TRY")  # "lane:k": that try alone
REPORT = os.environ.get("FLIGHTTEST_FUZZ_REPORT")  # a file to append each lane's tally to (JSON lines)
LANES = {"logs": 0.4, "plan": 0.25, "inputs": 0.2, "campaign": 0.15}  # shares of FUZZ_S
TRY_LIMIT_S = {"logs": 60.0, "plan": 120.0, "inputs": 60.0, "campaign": 30.0}  # a try past this: a hang
MEMORY_HEADROOM_BYTES = 3 << 30  # address space a try may add: more is an allocation no input should cause
DATA = Path(__file__).parent / "data"
REAL_LOGS = {"real.tlog": "px4_sih_vertical_head.tlog", "real.ulg": "px4_sih_vertical_head.ulg",
             "real.bin": "ardupilot_sitl_vertical_head.bin"}  # fmt: skip
PROFILES = ("x500", "arducopter_sitl", "mambo", "sih_quadx", "tunnel_rig")
# what Python's default filters never show a user (the others reach stderr from the real command)
HIDDEN_WARNINGS = (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning)
# the lines of flighttest's catch-alls, where an exception nobody expected ends up as one line ("analysis failed
# (TypeError: ...)"); the log readers' own failures on damaged content ("cannot parse ULog (...)") are the
# loaders' contract, not a catch-all's
CATCH_ALL = re.compile(
    r"analysis failed \(|identification failed \(|writing the report failed \(|"
    r"unexpected error|cannot plan the \w+ mission from"
)


# -- values ---------------------------------------------------------------------------------------------

EDGE_NUMBERS = (
    "0", "-0", "0.0", "1e-300", "5e-324", "-5e-324", "1e-320", "1e-12", "1e-6", "0.001", "1", "-1", "2.5",
    "1e6", "1e308", "-1e308", "1.7976931348623157e308", "1e400", "inf", "-inf", "nan", "NaN", "+1", "1_0",
    "0x10", "1,5", "١٢", "", " ", "abc", "9" * 400, "1e-", "--1", "1e5000", "-1e-320",
)  # fmt: skip


def number(rng: random.Random, lo: float = 0.0, hi: float = 10.0, integer: bool = False) -> str:
    """A command-line number: mostly inside ``[lo, hi]``, else an edge (near zero, huge, non-finite, not a number)."""
    r = rng.random()
    if r < 0.55:
        v = rng.uniform(lo, hi)
        return str(round(v)) if integer else repr(v)
    if r < 0.7:  # the ends of the range and just past them
        v = rng.choice([lo, hi])
        return str(int(v) + rng.choice([-1, 0, 1])) if integer else repr(v * (1 + rng.choice([-1e-12, 0.0, 1e-12])))
    if r < 0.8:  # log-uniform over the whole double range, either sign
        return repr(rng.choice([1, -1]) * 10 ** rng.uniform(-320, 308))
    return rng.choice(EDGE_NUMBERS)


def toml_number(rng: random.Random) -> str:
    """A number as a TOML literal (what a damaged profile or config holds)."""
    if rng.random() < 0.3:
        return repr(10 ** rng.uniform(-12, 6))
    return rng.choice(["0.0", "1e-300", "5e-324", "1e-12", "1e-6", "-1.0", "1e308", "inf", "nan", "-inf", "0",
                       "1e-9", "3", "1e6", '"1.0"', "true"])  # fmt: skip


def prepare_case(case: Path) -> None:
    """The things of every kind a path may name, in the try's folder."""
    (case / "afile").write_text("a file, not a folder\n")
    (case / "adir").mkdir()
    (case / "adir.png").mkdir()
    os.mkfifo(case / "fifo")
    os.symlink("loop", case / "loop")
    os.symlink("nowhere/at/all", case / "dangling")


def any_path(rng: random.Random, name: str = "out", suffix: str = "") -> str:
    """A path: mostly a plain one under the try's folder, else one of the kinds a command must refuse (or take)."""
    if rng.random() < 0.6:
        return rng.choice(["", "sub/", "new/deeper/"]) + name + suffix
    return rng.choice([
        "", " ", "a\nb" + suffix, "tab\tname" + suffix, "x" * 300 + suffix, "/".join(["d" * 200] * 20) + suffix,
        "/".join(["e" * 200] * 19) + "/" + name + suffix, "afile", "afile/x" + suffix, "adir", "adir/",
        "adir.png", "fifo", "loop", "loop/x" + suffix, "dangling", "/dev/null", ".", "..", "résumé/ø" + suffix,
        os.fsdecode(b"\xff\xfe") + suffix, "-x" + suffix, name + suffix + "/", "./" + name + suffix,
    ])  # fmt: skip


def vehicle(rng: random.Random, case: Path) -> str:
    """A profile: a shipped one, or a copy with one number replaced, or a path of another kind."""
    r = rng.random()
    if r < 0.55:
        return rng.choice(PROFILES)
    if r < 0.9:
        src = (SHIPPED_DIR / f"{rng.choice(PROFILES)}.toml").read_text(encoding="utf-8")
        keys = re.findall(r"(?m)^(\w+)\s*=\s*[-0-9.]", src)
        text = src
        for _ in range(rng.randint(1, 2)):
            key = rng.choice(keys)
            text = re.sub(rf"(?m)^{key}\s*=\s*[^#\n]*", f"{key} = {toml_number(rng)} ", text, count=1)
        path = case / f"prof{rng.randrange(1000)}.toml"
        path.write_text(text, encoding="utf-8")
        return str(path)
    return rng.choice(["", "nosuch", "fifo", "adir", "afile", "../x500", "x" * 300, "a\nb"])


# -- logs -----------------------------------------------------------------------------------------------


def byte_mutation(rng: random.Random, data: bytes) -> bytes:
    """One to four of: a bit flipped, bytes written over, inserted or deleted, the rest cut off, a chunk
    duplicated (half of them near the start, where headers and format definitions are)."""
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        if not b:
            break
        frac = rng.random() * (0.02 if rng.random() < 0.5 else 1.0)
        i, n = min(int(frac * len(b)), len(b) - 1), rng.randint(1, 4096)
        blob = bytes(rng.randrange(256) for _ in range(rng.randint(1, 64)))
        op = rng.choice(["flip", "overwrite", "insert", "delete", "truncate", "duplicate"])
        if op == "flip":
            b[i] ^= 1 << rng.randrange(8)
        elif op == "overwrite":
            b[i : i + len(blob)] = blob
        elif op == "insert":
            b[i:i] = blob
        elif op == "delete":
            del b[i : i + n]
        elif op == "truncate":
            del b[i:]
        else:
            b[i:i] = b[i : i + n]
    return bytes(b)


def tlog_records(data: bytes) -> list[bytes]:
    """A tlog's records, each ``[8-byte UNIX µs][frame]`` (up to the first that does not parse)."""
    out, pos = [], 0
    while pos + 16 <= len(data):
        magic = data[pos + 8]
        if magic == 0xFD:
            flen = 12 + data[pos + 9] + (13 if data[pos + 10] & 1 else 0)
        elif magic == 0xFE:
            flen = 8 + data[pos + 9]
        else:
            break
        out.append(data[pos : pos + 8 + flen])
        pos += 8 + flen
    return out


# the streams a loaded log's state comes from: position, attitude, IMU, heights
STATE_STREAMS = frozenset(getattr(dialect, f"MAVLINK_MSG_ID_{name}") for name in (
    "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "ODOMETRY", "ATTITUDE_QUATERNION", "ATTITUDE", "HIGHRES_IMU",
    "SCALED_IMU", "ALTITUDE", "SCALED_PRESSURE", "DISTANCE_SENSOR", "GPS_RAW_INT"))  # fmt: skip
_INT_LIMITS = {"B": (0, 255), "b": (-128, 127), "H": (0, 65535), "h": (-32768, 32767), "I": (0, 2**32 - 1),
               "i": (-(2**31), 2**31 - 1), "Q": (0, 2**64 - 1), "q": (-(2**63), 2**63 - 1)}  # fmt: skip


def _numeric_fields(msg) -> list[tuple[str, str]]:
    """(name, struct code) of a message's scalar numeric fields."""
    codes = re.findall(r"(\d*)([A-Za-z])", type(msg).unpacker.format.lstrip("<"))
    return [(n, c) for n, (count, c) in zip(msg.ordered_fieldnames, codes) if not count and c in "fdBbHhIiQq"]


def _extreme_value(rng: random.Random, code: str) -> float | int:
    if code in "fd":
        return rng.choice([float("inf"), float("-inf"), float("nan"), 1e30, -1e30, 3.4e38, -3.4e38, 1e-38, 0.0, 1e3,
                           1e6, -1e6, 1e10])  # fmt: skip
    lo, hi = _INT_LIMITS[code]
    return rng.choice([lo, hi, 0, (lo + hi) // 2])


def _repacked(mav, record: bytes, name: str | None = None, value: float | int | None = None,
              rng: random.Random | None = None) -> bytes:  # fmt: skip
    """The record with field ``name`` of its message set to ``value`` (else a random field to an extreme value),
    re-packed with a valid CRC: damage the reader's checksum cannot catch."""
    try:
        msg = mav.decode(bytearray(record[8:]))
    except Exception:
        return record
    fields = dict(_numeric_fields(msg))
    if name is None:
        if not fields or rng is None:
            return record
        name = rng.choice(sorted(fields))
        value = _extreme_value(rng, fields[name])
    if name not in fields:
        return record
    setattr(msg, name, value)
    mav.srcSystem, mav.srcComponent = msg.get_srcSystem(), msg.get_srcComponent()
    try:
        return record[:8] + msg.pack(mav)
    except Exception:
        return record


def _msgid(record: bytes) -> int:
    if record[8] == 0xFD:
        return record[15] | record[16] << 8 | record[17] << 16
    return record[13]


def tlog_mutation(rng: random.Random, data: bytes) -> bytes:
    """Record-level damage a byte flip rarely makes: timestamps rewritten (shifted, scaled, shuffled, random,
    equal), messages re-packed around extreme values (single ones, or one field of one message type for a run
    of its messages), records dropped, repeated or swapped."""
    recs = tlog_records(data)
    if len(recs) < 4:
        return byte_mutation(rng, data)
    tail = data[sum(map(len, recs)) :]
    for _ in range(rng.randint(1, 3)):
        op = rng.choice(["time_shift", "time_scale", "time_shuffle", "time_random", "time_equal", "extreme",
                         "stream", "stream", "stream", "drop", "repeat", "swap"])  # fmt: skip
        i = rng.randrange(len(recs))
        j = min(len(recs), i + rng.choice([1, 5, 50, 500, len(recs)]))
        stamps = [struct.unpack_from(">Q", r)[0] for r in recs[i:j]]
        if op == "time_shift":
            d = rng.choice([-1, 1]) * 10 ** rng.randint(3, 13)
            stamps = [(s + d) % 2**64 for s in stamps]
        elif op == "time_scale":
            k, s0 = rng.choice([0.0, 1e-3, 10.0, 1e3, 1e6]), stamps[0]
            stamps = [int(s0 + (s - s0) * k) % 2**64 for s in stamps]
        elif op == "time_shuffle":
            rng.shuffle(stamps)
        elif op == "time_random":
            stamps = [rng.getrandbits(64) if rng.random() < 0.3 else s for s in stamps]
        elif op == "time_equal":
            stamps = [stamps[0]] * len(stamps)
        if op.startswith("time"):
            recs[i:j] = [struct.pack(">Q", s) + r[8:] for s, r in zip(stamps, recs[i:j])]
        elif op == "extreme":  # single records anywhere, any field
            mav = dialect.MAVLink(None)
            for k in rng.sample(range(len(recs)), min(len(recs), rng.choice([1, 10, 40]))):
                recs[k] = _repacked(mav, recs[k], rng=rng)
        elif op == "stream":  # one field of one message type gone wrong for a run of its messages (a sensor)
            mav = dialect.MAVLink(None)
            ids = sorted({_msgid(r) for r in recs})
            state = [i for i in ids if i in STATE_STREAMS]  # what the analysis is made of, mostly
            wanted = rng.choice(state if state and rng.random() < 0.8 else ids)
            same = [k for k in range(len(recs)) if _msgid(recs[k]) == wanted]
            start = rng.randrange(len(same))
            run = same[start : start + rng.choice([3, 10, 30, 100, len(same)])]
            try:
                sample = mav.decode(bytearray(recs[run[0]][8:]))
                name, code = rng.choice(_numeric_fields(sample))
            except Exception:
                continue
            value = _extreme_value(rng, code)
            for k in run:
                recs[k] = _repacked(mav, recs[k], name, value)
        elif op == "drop":
            del recs[i:j]
        elif op == "repeat":
            recs[j:j] = recs[i:j]
        elif len(recs) > 1:
            k = rng.randrange(len(recs))
            recs[i], recs[k] = recs[k], recs[i]
        if not recs:
            break
    return b"".join(recs) + tail


@dataclass
class Seeds:
    """The logs the lanes start from: bytes by name, and a flighttest probe folder."""

    files: dict[str, bytes]
    probe_folder: Path


@pytest.fixture(scope="module")
def seeds(tmp_path_factory) -> Seeds:
    from synthetic import SyntheticFlight, write_dataflash, write_tlog, write_ulog
    from test_identify_refuses import log_folder, probe_flight

    d = tmp_path_factory.mktemp("seeds")
    files = {name: (DATA / src).read_bytes() for name, src in REAL_LOGS.items()}
    short = SyntheticFlight(duration_s=4.0, descents=[(1.0, 1.5, 1.2)])
    for writer, name in ((write_tlog, "syn.tlog"), (write_ulog, "syn.ulg"), (write_dataflash, "syn.bin")):
        files[name] = writer(short, d / name).read_bytes()
    probe = SyntheticFlight(duration_s=30.0, descents=[], probe=(6.0, 2.0, 0.02, 20.0), onset_mps=0.7)
    files["probe.tlog"] = write_tlog(probe, d / "probe.tlog", rate_hz=25.0).read_bytes()
    folder = log_folder(d / "20260101-000000-probe", flight=probe_flight(0.7))
    return Seeds(files, folder)


# -- running a try ---------------------------------------------------------------------------------------


class _Hang(BaseException):
    """Raised by the alarm: a BaseException, past every ``except Exception`` of the code under test."""


@dataclass
class Outcome:
    rc: int | None
    out: str
    err: str
    error: str | None = None  # the exception that left main, with the end of its traceback
    warned: list[str] = field(default_factory=list)
    seconds: float = 0.0


def _tree(root: Path) -> set[str]:
    out = set()
    for dirpath, dirnames, filenames in os.walk(root):
        out.update(os.path.join(dirpath, n) for n in dirnames + filenames)
    return out


@contextlib.contextmanager
def _bounded(seconds: float) -> Iterator[None]:
    """An alarm after ``seconds`` and an address-space cap ``MEMORY_HEADROOM_BYTES`` above today's, for one try."""

    def _alarm(signum, frame):
        raise _Hang(f"no answer within {seconds:g} s")

    old_handler = signal.signal(signal.SIGALRM, _alarm)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/statm") as f:
        used = int(f.read().split()[0]) * resource.getpagesize()
    cap = used + MEMORY_HEADROOM_BYTES
    resource.setrlimit(resource.RLIMIT_AS, (cap if hard == resource.RLIM_INFINITY else min(cap, hard), hard))
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old_handler)
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def run_cli(argv: list[str], case: Path, env: dict[str, str], limit_s: float) -> Outcome:
    """``main(argv)`` in ``case`` with ``env`` set, its output captured, bounded in time and memory."""
    saved_env, saved_cwd = dict(os.environ), os.getcwd()
    # encoded as a terminal's streams are (stdout strict, stderr backslashreplace): a file name that is not
    # UTF-8 printed to stdout fails here as it would there
    out = io.TextIOWrapper(io.BytesIO(), encoding="utf-8", errors="strict", write_through=True)
    err = io.TextIOWrapper(io.BytesIO(), encoding="utf-8", errors="backslashreplace", write_through=True)
    t0 = time.monotonic()
    result = Outcome(None, "", "")
    try:
        os.environ.update(env)
        os.chdir(case)
        with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stdout(out), \
                contextlib.redirect_stderr(err), _bounded(limit_s):  # fmt: skip
            warnings.simplefilter("always")
            try:
                result.rc = main(list(argv))
            except BaseException as exc:  # what left main is the finding
                tb = traceback.format_exception(exc)
                result.error = f"{type(exc).__name__}: {exc}"[:300] + " | " + "".join(tb[-3:])[-900:]
        result.warned = [f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})" for w in caught
                         if not issubclass(w.category, HIDDEN_WARNINGS)]  # fmt: skip
    finally:
        os.chdir(saved_cwd)
        os.environ.clear()
        os.environ.update(saved_env)
        from flighttest import console as consoles

        for c in (consoles.console, consoles.err_console):  # a failed write leaves its text in rich's buffer,
            del c._buffer[:]  # and every later try would fail on it
            c._buffer_index = 0
        import matplotlib.pyplot as plt

        plt.close("all")
    result.out, result.err = (s.buffer.getvalue().decode("utf-8", "replace") for s in (out, err))
    result.seconds = time.monotonic() - t0
    return result


def check(argv: list[str], res: Outcome, written: set[str], ok_codes: frozenset[int] = frozenset({0, 2})) -> str | None:
    """What broke the commands' contract in this try (module docstring), or None."""
    if res.error is not None:
        return f"exception out of main: {res.error}"
    for text in (res.out, res.err):
        if "Traceback" in text:
            return "a traceback in the output"
        if m := CATCH_ALL.search(text):
            line = next(ln for ln in text.splitlines() if m.group(0) in ln)
            return f"a catch-all's message: {line[:300]}"
    if res.warned:
        return f"a warning: {res.warned[0][:300]}"
    if res.rc not in ok_codes:
        return f"exit code {res.rc}: {res.err.strip()[-300:]}"
    lines = [ln for ln in res.err.splitlines() if ln.strip()]
    if res.rc == 2 and not all(ln.startswith("flighttest: ") for ln in lines):
        return f"exit 2 with more on stderr than flighttest's lines: {res.err[:300]!r}"
    errors = [ln for ln in lines if ln.startswith("flighttest: error:")]
    per_log = argv[0] in ("analyse", "compare", "report")
    if res.rc == 2 and (not errors or (len(errors) > 1 and not per_log)):
        return f"exit 2 with {len(errors)} error lines: {res.err[:300]!r}"
    if "--json" in argv:
        try:
            doc = json.loads(res.out)
        except ValueError:
            return f"--json printed no single JSON document: {res.out[:200]!r}"
        if res.rc == 2 and not per_log and not (isinstance(doc, dict) and "error" in doc):
            return f"--json exit 2 without an error key: {res.out[:200]!r}"
    if res.rc == 2 and argv[0] != "analyse" and written:
        return f"exit 2 but wrote {sorted(written)[:5]}"
    return None


@dataclass
class Finding:
    lane: str
    k: int
    argv: list[str]
    what: str
    kept: str | None = None  # where the try's input log was kept


def run_lane(lane: str, tmp: Path, make_try: Callable[[random.Random, Path], tuple[list[str], dict, frozenset]],
             keep: Callable[[Path, Path], str | None] | None = None) -> None:  # fmt: skip
    """Tries of ``lane`` until its share of ``FUZZ_S`` is spent (or the one try ``FLIGHTTEST_FUZZ_TRY`` names);
    fails listing every finding, each with how to replay it."""
    if ONLY is not None and ONLY.split(":")[0] != lane:
        return
    budget = FUZZ_S * LANES[lane]
    tries = [int(ONLY.split(":")[1])] if ONLY is not None else None
    findings: list[Finding] = []
    t_end, k, done = time.monotonic() + budget, 0, 0
    codes: dict[str, int] = {}  # exit code → tries: how many were refused, how many went through
    while (tries is None and time.monotonic() < t_end) or (tries is not None and tries):
        k = tries.pop() if tries is not None else k + 1
        case = tmp / f"{lane}-{k}"
        case.mkdir()
        prepare_case(case)
        rng = random.Random(f"{SEED}:{lane}:{k}")
        argv, env, ok_codes = make_try(rng, case)
        env = {"HOME": str(case / "home"), "FLIGHTTEST_VEHICLES": str(case / "vehicles"), **env}
        before = _tree(case)
        res = run_cli(argv, case, env, TRY_LIMIT_S[lane])
        what = check(argv, res, _tree(case) - before, ok_codes)
        done += 1
        codes[str(res.rc)] = codes.get(str(res.rc), 0) + 1
        if what is not None:
            kept = keep(case, tmp / "findings" / f"{lane}-{k}") if keep else None
            findings.append(Finding(lane, k, argv, what, kept))
        shutil.rmtree(case, ignore_errors=True)
    tally = {"lane": lane, "seed": SEED, "seconds": budget, "tries": done, "exit_codes": codes,
             "findings": len(findings), "found": [f"{f.lane}:{f.k} {f.what[:160]}" for f in findings[:20]]}  # fmt: skip
    print(json.dumps(tally))
    if REPORT:
        with open(REPORT, "a", encoding="utf-8") as fh:
            fh.write(json.dumps(tally) + "\n")
    assert not findings, f"{len(findings)} of {done} tries broke the contract (replay: FLIGHTTEST_FUZZ_SEED={SEED} " \
        "FLIGHTTEST_FUZZ_TRY=lane:k):\n" + "\n".join(
            f"  {f.lane}:{f.k} {f.what}\n    argv {f.argv!r}" + (f"\n    input kept in {f.kept}" if f.kept else "")
            for f in findings[:12])  # fmt: skip


def _limit(budget_share: float) -> float:
    return FUZZ_S * budget_share + 300.0  # pytest-timeout's hard stop: the lane's time and a hung try's


# -- the lanes -------------------------------------------------------------------------------------------

LOG_NAMES = ("real.tlog", "real.ulg", "real.bin", "syn.tlog", "syn.ulg", "syn.bin", "probe.tlog", "folder")


def _log_try(seeds: Seeds) -> Callable[[random.Random, Path], tuple[list[str], dict, frozenset]]:
    def make(rng: random.Random, case: Path) -> tuple[list[str], dict, frozenset]:
        command = rng.choices(["identify", "analyse", "compare", "report"], [4, 4, 1, 1])[0]
        # identify fits a probe's sweep: most of its tries start from one, so the fit itself is reached
        probe = command == "identify" and rng.random() < 0.7
        name = rng.choice(["probe.tlog", "folder"]) if probe else rng.choice(LOG_NAMES)
        if name == "folder":  # the probe folder, its tlog or a side file damaged
            path = case / "20260101-000000-probe"
            shutil.copytree(seeds.probe_folder, path)
            target = path / rng.choice(["flight.tlog", "flight.tlog", "meta.json", "events.jsonl", "setpoints.csv"])
            data = target.read_bytes()
            target.write_bytes(tlog_mutation(rng, data) if target.suffix == ".tlog" and rng.random() < 0.6
                               else byte_mutation(rng, data))  # fmt: skip
        else:
            data = seeds.files[name]
            tlog = name.endswith(".tlog")
            path = case / rng.choice([name, name, "flight.dat", "noext"])
            path.write_bytes(tlog_mutation(rng, data) if tlog and rng.random() < 0.6 else byte_mutation(rng, data))
        as_json = ["--json"] if rng.random() < 0.7 and command != "report" else []
        if command == "identify":
            argv = ["identify", str(path), "--vehicle", "x500", *as_json]
        elif command == "analyse":
            argv = ["analyse", str(path), "--jobs", "1", *(["--vehicle", "x500"] if rng.random() < 0.6 else []),
                    *as_json]  # fmt: skip
        elif command == "compare":
            other = case / "other.tlog"
            other.write_bytes(seeds.files["syn.tlog"])
            argv = ["compare", str(other), str(path), *as_json]
        else:
            argv = ["report", str(path), "-o", "report", "--vehicle", "x500"]
        return argv, {}, frozenset({0, 2})

    return make


def _keep_log(case: Path, dest: Path) -> str:
    dest.parent.mkdir(parents=True, exist_ok=True)
    shutil.copytree(case, dest, ignore=shutil.ignore_patterns("fifo", "loop", "dangling"), symlinks=True)
    return str(dest)


@pytest.mark.timeout(_limit(LANES["logs"]))
def test_fuzz_logs(seeds, tmp_path):
    run_lane("logs", tmp_path, _log_try(seeds), keep=_keep_log)


PLAN_OPTIONS = {  # option: (lo, hi) of a value that plans, as the option's range has it
    "vertical": {"--height": (0.1, 20.0), "--w-allow": (0.01, 3.0), "--margin": (0.0, 1.0),
                 "--extra-margin": (0.0, 1.0), "--accel-fraction": (0.0, 1.0)},
    "probe": {"--amplitude": (0.1, 10.0), "--omega0": (0.0, 0.2), "--ramp": (0.0, 10.0),
              "--max-descent-speed": (0.0, 5.0), "--duration": (0.0, 120.0), "--start-alt": (0.0, 30.0),
              "--floor": (0.0, 10.0), "--speed-step": (0.01, 1.0)},
    "helix": {"--height": (0.1, 10.0), "--radius": (0.0, 5.0), "--tilt-max": (0.0, 90.0),
              "--rate-max": (0.0, 400.0), "--thrust-fraction": (0.0, 1.0), "--margin": (0.0, 1.0)},
    "planar": {"--height": (0.1, 10.0), "--y-bound": (0.0, 20.0), "--omega-max": (0.0, 10.0),
               "--f-min": (-10.0, 10.0), "--f-max": (0.0, 40.0), "--v-bound": (0.0, 10.0), "--margin": (0.0, 1.0)},
}  # fmt: skip


def _plan_try(rng: random.Random, case: Path) -> tuple[list[str], dict, frozenset]:
    kind = rng.choices(["vertical", "probe", "helix", "planar"], [4, 4, 1, 1])[0]
    argv = ["plan", kind, "--vehicle", vehicle(rng, case)]
    options = PLAN_OPTIONS[kind]
    for opt in rng.sample(sorted(options), rng.randint(0, min(4, len(options)))):
        argv += [opt, number(rng, *options[opt])]
    if kind in ("helix", "planar"):  # a mesh small enough to solve in seconds (its range is checked elsewhere)
        argv += ["--intervals", rng.choice(["10", "12", "15"])]
        if kind == "helix" and rng.random() < 0.3:
            argv += ["--wind", number(rng, -5, 5), number(rng, -5, 5), number(rng, -2, 2)]
        if kind == "planar" and rng.random() < 0.2:
            argv += ["--case", rng.choice(["1", "3", "6", "0", "7"])]
    argv += ["-o", any_path(rng, "plan")]
    if rng.random() < 0.1:
        argv += ["--plot", any_path(rng, "fig", rng.choice([".png", ".svg", ".txt", ""]))]
    if rng.random() < 0.5:
        argv.append("--json")
    # a solve that does not converge is exit 1 with its status (flighttest plan's contract)
    return argv, {}, frozenset({0, 1, 2}) if kind in ("helix", "planar") else frozenset({0, 2})


@pytest.mark.timeout(_limit(LANES["plan"]))
def test_fuzz_plan_options(tmp_path):
    run_lane("plan", tmp_path, _plan_try)


def _walk_folder(rng: random.Random, case: Path, seeds: Seeds) -> Path:
    """A folder to analyse with oddly named things inside."""
    root = case / f"walk{rng.randrange(10**6)}"
    if root.exists():
        return root
    root.mkdir()
    (root / "good.tlog").write_bytes(seeds.files["syn.tlog"])
    for _ in range(rng.randint(0, 3)):
        name = rng.choice(["bad\nname.tlog", "tab\tx.tlog", "y" * 250 + ".tlog", "sub\ndir", "fifo.tlog", "loop",
                           "empty.tlog", "deep", "z.bin", os.fsdecode(b"\xff.tlog")])  # fmt: skip
        path = root / name
        if path.exists() or path.is_symlink():
            continue
        if name == "fifo.tlog":
            os.mkfifo(path)
        elif name == "loop":
            os.symlink("loop", path)
        elif name == "empty.tlog":
            path.write_bytes(b"")
        elif name in ("sub\ndir", "deep"):
            inner = path.joinpath(*(["q" * 200] * (18 if name == "deep" else 1)))
            inner.mkdir(parents=True)
            (inner / "in.tlog").write_bytes(seeds.files["syn.tlog"])
        else:
            path.write_bytes(seeds.files["syn.tlog"])
    return root


def _vehicles_env(rng: random.Random, case: Path) -> dict[str, str]:
    """The user profile folder identify --write-profile writes to: missing, there, or of another kind."""
    kind = rng.choice(["missing", "folder", "file", "fifo", "toml-folder", "long", "newline", "empty", "two"])
    v = case / "vehicles"
    if kind == "folder":
        v.mkdir()
    elif kind == "file":
        v.write_text("x\n")
    elif kind == "fifo":
        os.mkfifo(v)
    elif kind == "toml-folder":
        (v / "x500.toml").mkdir(parents=True)
    elif kind == "long":
        return {"FLIGHTTEST_VEHICLES": str(case / ("v" * 300))}
    elif kind == "newline":
        return {"FLIGHTTEST_VEHICLES": str(case / "a\nb")}
    elif kind == "empty":
        return {"FLIGHTTEST_VEHICLES": ""}
    elif kind == "two":
        return {"FLIGHTTEST_VEHICLES": f"{case / 'afile'}{os.pathsep}{v}"}
    return {"FLIGHTTEST_VEHICLES": str(v)}


def _inputs_try(seeds: Seeds) -> Callable[[random.Random, Path], tuple[list[str], dict, frozenset]]:
    def log(rng: random.Random, case: Path) -> str:
        r = rng.random()
        if r < 0.5:
            name = rng.choice(["probe.tlog", "syn.tlog", "real.tlog", "real.ulg", "syn.bin"])
            (case / name).write_bytes(seeds.files[name])
            return name
        if r < 0.65:
            shutil.copytree(seeds.probe_folder, case / "probe-folder", dirs_exist_ok=True)
            return "probe-folder"
        if r < 0.8:
            return str(_walk_folder(rng, case, seeds))
        return any_path(rng, "log", rng.choice([".tlog", ""]))

    def make(rng: random.Random, case: Path) -> tuple[list[str], dict, frozenset]:
        command = rng.choices(["identify", "analyse", "compare", "report"], [4, 4, 1, 1])[0]
        env: dict[str, str] = {}
        if command == "identify":
            argv = ["identify", log(rng, case), "--vehicle", vehicle(rng, case)]
            if rng.random() < 0.4:
                argv += ["--threshold", number(rng, 1.0, 10.0)]
            if rng.random() < 0.6:
                argv.append("--write-profile")
                env = _vehicles_env(rng, case)
        elif command == "analyse":
            argv = ["analyse", *(log(rng, case) for _ in range(rng.randint(1, 3))), "--jobs",
                    rng.choice(["1", "1", "1", "2", "0", "-1", "100000", "x"])]  # fmt: skip
            for opt, lo, hi in (("--rate-threshold", 0.0, 1.0), ("--min-height", 0.0, 5.0), ("--start-tol", 0.0, 1.0),
                                ("--end-tol", 0.0, 1.0), ("--settle-hold", 0.0, 5.0)):  # fmt: skip
                if rng.random() < 0.15:
                    argv += [opt, number(rng, lo, hi)]
            if rng.random() < 0.3:
                argv += ["--vehicle", vehicle(rng, case)]
            if rng.random() < 0.2:
                argv += ["--csv", any_path(rng, "table", rng.choice([".csv", ".txt"]))]
            if rng.random() < 0.2:
                argv += ["--parquet", any_path(rng, "table", ".parquet")]
            if rng.random() < 0.2:
                argv.append("--wide")
        elif command == "compare":
            argv = ["compare", *(log(rng, case) for _ in range(rng.randint(1, 2)))]
            if rng.random() < 0.3:
                argv += ["--vehicle", vehicle(rng, case)]
        else:
            argv = ["report", log(rng, case), "-o", any_path(rng, "report"), "--vehicle", "x500"]
        if command != "report" and rng.random() < 0.6:
            argv.append("--json")
        return argv, env, frozenset({0, 2})

    return make


@pytest.mark.timeout(_limit(LANES["inputs"]))
def test_fuzz_analysis_inputs(seeds, tmp_path):
    run_lane("inputs", tmp_path, _inputs_try(seeds), keep=_keep_log)


SIM_PARAMS = ("MPC_Z_VEL_MAX_DN", "COM_OF_LOSS_T", "MIS_TAKEOFF_ALT", "COM_RC_OVERRIDE", "GUID_TIMEOUT", "NOPE", "")
URLS = ("udpin://0.0.0.0:14540", "udpout://127.0.0.1:9", "tcpout://127.0.0.1:1", "serial:///dev/null:57600",
        "serial:///dev/nosuch:57600", "udpout://localhost:0", "", "foo", "udpin://[::1]:14540",
        "udpout://127.0.0.1:99999", "udpin://0.0.0.0:", "serial://dev/ttyUSB0:57600",
        "udpout://1.2.3.4.5:1")  # fmt: skip
STEP_WORDS = ("probe", "identify", "plan", "vertical", "helix", "report", "nope", "")


def _campaign_record(rng: random.Random, path: Path) -> None:
    """A campaign.json in ``path``, well formed or damaged."""
    steps = {s: {"status": rng.choice(["pending", "done", "failed", "running", "interrupted", "weird"]),
                 "started_unix_s": rng.choice([1.7e9, None, "x", -1.0]), "elapsed_s": rng.choice([1.0, None, -5.0]),
                 "outputs": rng.choice([{}, {"log_dir": "flights/x"}, {"vertical": "../../etc"}, []]),
                 "error": rng.choice([None, "x", 3])}
             for s in ("probe", "identify", "plan", "vertical", "helix", "report")}  # fmt: skip
    doc = {"format": rng.choice(["flighttest-campaign/1", "flighttest-campaign/1", "other/9"]),
           "vehicle": rng.choice(["x500", "x500", "mambo", 3, "../x"]), "created_unix_s": 1.7e9,
           "steps": steps}  # fmt: skip
    text = json.dumps(doc)
    if rng.random() < 0.3:
        text = byte_mutation(rng, text.encode()).decode("utf-8", "replace")
    path.mkdir(parents=True, exist_ok=True)
    (path / "campaign.json").write_text(text, encoding="utf-8")


def _campaign_try(rng: random.Random, case: Path) -> tuple[list[str], dict, frozenset]:
    argv = ["campaign", *(["--sim"] if rng.random() < 0.7 else ["--connect", rng.choice(URLS)])]
    out = any_path(rng, "camp")
    if rng.random() < 0.25:
        out = "existing"
        _campaign_record(rng, case / out)
    argv += ["-o", out]
    if rng.random() < 0.4:
        argv += ["--vehicle", vehicle(rng, case)]
    if rng.random() < 0.3:
        argv += [rng.choice(["--only", "--from"]), rng.choice(STEP_WORDS)]
    if rng.random() < 0.2:
        argv += ["--stale-periods", number(rng, 1.0, 50.0)]
    if rng.random() < 0.2:
        argv += ["--truth-onset", number(rng, 0.01, 3.0)]
    if rng.random() < 0.2:
        argv += ["--sim-wind", *(number(rng, -10, 10) for _ in range(3))]
    if rng.random() < 0.2:
        argv += ["--sim-seed", number(rng, 0, 2**32, integer=True)]
    for _ in range(rng.choice([0, 0, 1, 2])):
        argv += ["--sim-param", f"{rng.choice(SIM_PARAMS)}={number(rng, 0, 10)}"]
    if rng.random() < 0.2:
        argv += ["--sim-autopilot", rng.choice(["px4", "ardupilot", "betaflight"])]
    if rng.random() < 0.5:
        argv.append("--json")
    assert "--yes" not in argv  # nothing may fly: without a terminal and --yes a campaign that would start is refused
    return argv, {}, frozenset({0, 2})


@pytest.mark.timeout(_limit(LANES["campaign"]))
def test_fuzz_campaign_options(tmp_path):
    run_lane("campaign", tmp_path, _campaign_try)
