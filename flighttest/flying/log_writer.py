"""One folder per flight (docs/CONTRACTS.md "Flight log folders"), written as the vehicle flies.

Rows go to open CSV / JSONL files, line-buffered: each row reaches the OS as one whole line the
moment it is written (a block buffer would hand the OS half a line whenever it fills, and a killed
process would leave that half). A process killed mid-flight, even with SIGKILL, so loses nothing it
wrote, every line in the files is complete, and the analysis tools read what is there.
``flush()`` is kept for callers that want to be explicit; ``FLUSH_EVERY_S`` bounds it anyway.
``summary.json`` is written last; its absence marks a flight that did not end cleanly.

No write ever raises during a flight: the guard, the ladder and the commands run on the same loop as
the writes, and a full disk must not stop them. A failed write (``OSError``) is counted; the first
error is kept, and ``summary.json`` says the log is incomplete (``log_complete``, ``log_write_errors``).
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import platform
import time
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import IO, Any

from flighttest.console import json_safe

FLUSH_EVERY_S = 0.5

SETPOINT_COLUMNS = (
    "t_s", "unix_s", "n_m", "e_m", "d_m", "vn_mps", "ve_mps", "vd_mps",
    "an_mps2", "ae_mps2", "ad_mps2", "yaw_deg", "phase",
)  # fmt: skip
GUARD_COLUMNS = (
    "t_s", "unix_s", "verdict", "w_mps", "u_mps", "margin_mps", "predicted_margin_mps", "action",
    "reason", "vn_mps", "ve_mps", "vd_mps", "qw", "qx", "qy", "qz", "wn_mps", "we_mps", "wd_mps", "alt_m",
    "wind_sd_mps", "wind_source", "gust_sd_mps",
)  # fmt: skip


# every file a flight log folder may hold (docs/CONTRACTS.md), for ``FlightLogWriter.discard``
LOG_FILES = frozenset({"meta.json", "flight.tlog", "setpoints.csv", "guard.csv", "events.jsonl", "preflight.json",
                       "params.json", "trajectory.csv", "trajectory.json", "summary.json"})  # fmt: skip


def default_log_root() -> Path:
    return Path(os.environ.get("FLIGHTTEST_LOG_DIR", "logs"))


def csv_number(v: Any) -> Any:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else f"{v:.6g}" if abs(v) < 1e5 else f"{v:.3f}"
    return v


def write_json_atomic(path: Path, data: Any) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(json_safe(data), indent=2) + "\n", encoding="utf-8")
    tmp.replace(path)


class _Sink:
    """One open log file whose writes never raise: a failure is counted by the writer it reports to."""

    def __init__(self, f: IO[str], failed: Callable[[OSError], None]) -> None:
        self.f = f
        self._failed = failed

    def write(self, text: str) -> None:
        try:
            self.f.write(text)
        except OSError as exc:
            self._failed(exc)

    def flush(self) -> None:
        try:
            if not self.f.closed:
                self.f.flush()
        except OSError as exc:
            self._failed(exc)

    def close(self) -> None:
        try:
            self.f.close()
        except OSError as exc:
            self._failed(exc)


class FlightLogWriter:
    """The open log folder of one flight. ``t_s`` columns count from ``t0_mono`` (mission start)."""

    def __init__(self, root: Path | str, mission: str, t0_mono: float | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:  # fmt: skip
        root = Path(root)
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in mission) or "flight"
        base = root / f"{stamp}-{safe}"
        # the folders this log creates above its own: a discarded log takes them away again
        self._made_parents = [p for p in (root, *root.parents) if not p.exists()]
        path, n = base, 1
        while True:
            try:
                path.mkdir(parents=True, exist_ok=False)
                break
            except FileExistsError:
                n += 1
                path = base.with_name(f"{base.name}-{n}")
            except OSError as exc:
                from flighttest.errors import FlighttestError

                raise FlighttestError(f"cannot create log folder {path} ({exc.strerror})") from None
        self.dir = path
        self.write_errors = 0
        self.first_error: str | None = None
        # ``clock`` is the runner's (its event loop's; virtual in the runner's tests): t0 on it, and the
        # wall time of t0 through it
        self.t0_mono = clock() if t0_mono is None else t0_mono
        self.unix0 = time.time() - (clock() - self.t0_mono)
        self._files: list[_Sink] = []
        self._setpoints = self._open_csv("setpoints.csv", SETPOINT_COLUMNS)
        self._guard = self._open_csv("guard.csv", GUARD_COLUMNS)
        self._events = self._open("events.jsonl")
        self._last_flush = time.monotonic()
        self.closed = False

    # -- paths -----------------------------------------------------------------------------------
    @property
    def tlog_path(self) -> Path:
        return self.dir / "flight.tlog"

    @property
    def complete(self) -> bool:
        return self.write_errors == 0

    def write_failed(self, exc: OSError) -> None:
        self.write_errors += 1
        if self.first_error is None:
            self.first_error = f"{exc.strerror or exc}" + (f": {Path(exc.filename).name}" if exc.filename else "")

    def log_state(self) -> dict[str, Any]:
        """What ``summary.json`` says of the log itself."""
        return {"log_complete": self.complete, "log_write_errors": self.write_errors,
                "log_first_error": self.first_error}  # fmt: skip

    def _open(self, name: str) -> _Sink:
        f = open(self.dir / name, "w", encoding="utf-8", newline="", buffering=1)  # noqa: SIM115 (kept open)
        sink = _Sink(f, self.write_failed)
        self._files.append(sink)
        return sink

    def _open_csv(self, name: str, columns: tuple[str, ...]):
        f = self._open(name)
        w = csv.writer(f, lineterminator="\n")
        w.writerow(columns)
        f.flush()
        return w

    def times(self, t_mono: float) -> tuple[float, float]:
        dt = t_mono - self.t0_mono
        return dt, self.unix0 + dt

    # -- rows ------------------------------------------------------------------------------------
    def setpoint(self, t_mono: float, phase: str, n, e, d, vn, ve, vd, an, ae, ad, yaw_deg) -> None:
        if self.closed:
            return
        t, u = self.times(t_mono)
        values = (t, u, n, e, d, vn, ve, vd, an, ae, ad, yaw_deg)
        self._setpoints.writerow([csv_number(float(x)) for x in values] + [phase])
        self.flush_if_due()

    def guard(self, decision, wind=None) -> None:
        """One guard decision with the inputs it was made from (``flighttest.flying.guard.Decision``) and the
        wind estimate it judged with (``flighttest.flying.wind.WindEstimate``; None: none)."""
        if self.closed:
            return
        t, u = self.times(decision.t_s)
        s = decision.sample
        inputs = (
            (s.vn_mps, s.ve_mps, s.vd_mps, s.qw, s.qx, s.qy, s.qz, s.wn_mps, s.we_mps, s.wd_mps, s.alt_m)
            if s is not None
            else (math.nan,) * 11
        )
        row = [t, u, decision.verdict, decision.w_mps, decision.u_mps, decision.margin_mps,
               decision.predicted_margin_mps, decision.action, decision.reason, *inputs,
               wind.sd_mps if wind is not None else math.nan, wind.source if wind is not None else "",
               wind.gust_sd_mps if wind is not None else math.nan]  # fmt: skip
        self._guard.writerow([csv_number(float(x)) if isinstance(x, float | int) else x for x in row])
        self.flush_if_due()

    def event(self, t_mono: float, event: str, **fields: Any) -> None:
        if self.closed:
            return
        t, u = self.times(t_mono)
        rec = {"t_s": round(t, 4), "unix_s": round(u, 4), "event": event, **fields}
        try:
            line = json.dumps(json_safe(rec), default=str) + "\n"
        except (TypeError, ValueError) as exc:  # a field that cannot be written must not stop the caller
            bare = {"t_s": rec["t_s"], "unix_s": rec["unix_s"], "event": event, "unwritable": repr(exc)}
            line = json.dumps(bare) + "\n"
        self._events.write(line)
        # events are rare and matter most when something goes wrong: flush them at once
        self.flush()

    # -- whole files -----------------------------------------------------------------------------
    def write_meta(self, meta: dict[str, Any]) -> None:
        from flighttest import __version__

        base = {
            "start_unix_s": round(self.unix0, 3),
            "versions": {"flighttest": __version__, "python": platform.python_version(), **_lib_versions()},
        }
        write_json_atomic(self.dir / "meta.json", {**base, **meta})

    def write_preflight(self, data: Any) -> None:
        write_json_atomic(self.dir / "preflight.json", data)

    def write_params(self, snapshot: dict[str, Any]) -> Path:
        """``params.json``: the autopilot parameters this flight flew with
        (``flighttest.analysis.params.snapshot`` builds the document)."""
        path = self.dir / "params.json"
        write_json_atomic(path, snapshot)
        return path

    def write_summary(self, summary: dict[str, Any]) -> None:
        write_json_atomic(self.dir / "summary.json", {**summary, "log_dir": str(self.dir)})

    def save_trajectory(self, traj) -> None:
        traj.save(self.dir / "trajectory")

    # -- flushing --------------------------------------------------------------------------------
    def flush_if_due(self) -> None:
        if time.monotonic() - self._last_flush >= FLUSH_EVERY_S:
            self.flush()

    def flush(self) -> None:
        for f in self._files:
            f.flush()
        self._last_flush = time.monotonic()

    def close(self) -> None:
        if self.closed:
            return
        self.flush()
        for f in self._files:
            f.close()
        self.closed = True

    def discard(self) -> None:
        """Remove the folder of a flight that never started (nothing connected, nothing flown): its empty
        ``.tlog`` and header-only CSVs hold nothing and would trip the analysis tools up later. Only
        the files a flight log writes go; anything else keeps the folder (and the folders above it)."""
        self.close()
        for p in self.dir.iterdir():
            if p.name in LOG_FILES or p.name.endswith(".tmp"):
                with contextlib.suppress(OSError):
                    p.unlink()
        for d in (self.dir, *self._made_parents):
            try:
                d.rmdir()
            except OSError:  # not empty (or already gone): leave it and everything above it
                break


def _lib_versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in ("mavsdk", "pymavlink", "numpy"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "?"
    return out
