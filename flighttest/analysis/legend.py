"""What every column of the descent and comparison tables means: one text per header, shared by the
terminal tables (``flighttest analyse|compare``) and the Markdown reports (``report.md``, the
campaign's ``summary.md``), so a header never means two things."""

from __future__ import annotations

from flighttest.analysis.descent_time import HOVER_RULE, RATE_WINDOW_S, DescentRule
from flighttest.analysis.exposure import NEAR_MPS
from flighttest.flying.wind import WIND_COVERAGE_SIGMAS

MAIN_MARK = "*"  # after the number of the flight's main descent

COLUMNS: dict[str, str] = {
    "#": f"the descent's number in the log; {MAIN_MARK} marks the flight's main descent",
    "start s": "when it began, in seconds from the log's first sample (the main descent: its first setpoint)",
    "duration s": "how long it took (the main descent: until at its end height and settled, the descent time)",
    "start m": "its start height above the ground the vehicle stood on at arming",
    "height m": "how far it descended",
    "mean m/s": "its height over its duration",
    "max m/s": f"the height's fastest fall over {RATE_WINDOW_S:g} s (never below the mean)",
    "horiz. m": "how far it went sideways from where it began",
    "inside s": "time inside the guard region: the blade-frame descent through the disk w above "
    "max(w_allow, tan(cone)·u) - margin, air-relative with the wind as estimated, judged with the profile "
    "named for the flight",
    "inside, worst air s": "the same at the worst air within the wind estimate's uncertainty "
    f"({WIND_COVERAGE_SIGMAS:g} σ) and the updraft the guard allowed for the gusts, as the live guard judges",
    "inside worst s": "time inside the guard region at the worst air within the wind estimate's uncertainty "
    f"({WIND_COVERAGE_SIGMAS:g} σ) and the updraft the guard allowed for the gusts, as the live guard judges",
    "near s": f"time outside the guard region but within {NEAR_MPS:g} m/s of its boundary",
    "min margin m/s": "its closest approach to the guard region's boundary (negative: inside it)",
    "wind m/s": "the horizontal wind the descent was judged with (its mean over the descent)",
    "fluct. max": "the peak fluctuation index: body-rate, vertical-acceleration and motor shaking "
    "over the hover's (1 = hover, 2 = twice the hover's shake)",
    "phase": "the flight phase it began in (stream: the planned descent; land: the landing; "
    "abort, abort_*: flown by the abort ladder)",
    "outcome": "how the flight ended (completed, aborted, probe_stopped, ...)",
    "descent s": "descent time: from the first setpoint of the planned descent until the vehicle is at "
    f"its end height with its vertical speed settled ({DescentRule().describe()}); logs of other "
    "programs: the main descent's duration",
    "planned s": "the plan timed by the same rule: what the descent takes when flown exactly",
    "hover→hover s": f"from the first setpoint of the planned descent until {HOVER_RULE.describe()}",
    "÷ optimum": "hover to hover over the planner's optimum for the same vehicle, height, end point and wind "
    "(no guard margin, the vehicle's full limits; 1 = flown as fast as the planner can)",
    "horiz. err m": "off the end point sideways at that instant",
    "speed-up ×": "the first log's descent time over this one's (– where they differ in start "
    "height or height, unless --allow-unequal)",
}


def lines(headers, indent: str = "  ") -> list[str]:
    """``header: meaning`` for each of ``headers`` that has one, in order."""
    return [f"{indent}{h}: {COLUMNS[h]}" for h in headers if h in COLUMNS]


def _n(v, fmt: str = "{:.2f}") -> str:
    return fmt.format(v) if isinstance(v, int | float) else "–"


def judged_text(judged: dict | None) -> str:
    """Which profile judged the flight (``Analysis.judged_with``), in words."""
    if not judged:
        return "no vehicle profile: the guard region was not judged (give --vehicle)"
    w = f"w_allow {_n(judged.get('w_allow_mps'), '{:.3f}')} m/s"
    flown = judged.get("flown_w_allow_mps")
    if judged.get("basis") == "as flown":
        return f"{judged.get('vehicle')} as it flew ({w}, from the flight's meta.json)"
    also = (f"; it flew with {_n(flown, '{:.3f}')} m/s" if isinstance(flown, int | float)
            and abs(flown - (judged.get("w_allow_mps") or 0.0)) >= 5e-4 else "")  # fmt: skip
    how = "--vehicle" if judged.get("basis") == "given" else "today's profile"
    return f"{judged.get('vehicle')} ({how}: {w}){also}"


def main_text(main: dict | None, note: str | None = None) -> str:
    """The main descent in one sentence (``Analysis.main``; ``note`` why there is none)."""
    if main is None:
        return f"no main descent: {note}" if note else "no main descent"
    figures = (f"{_n(main.get('height_m'))} m from {_n(main.get('start_height_m'))} m, mean "
               f"{_n(main.get('mean_rate_mps'))} m/s, max {_n(main.get('max_rate_mps'))} m/s")  # fmt: skip
    planned = main.get("planned_descent_s")
    plan = f", planned {_n(planned)} s" if isinstance(planned, int | float) else ""
    if main.get("basis") != "planned descent":
        text = f"{_n(main.get('duration_s'))} s (log segment{plan}): {figures}"
    elif main.get("descent_time_s") is not None:
        text = (f"{_n(main.get('descent_time_s'))} s{plan}: {figures}, "
                f"{_n(main.get('horizontal_error_m'))} m off the end point sideways")  # fmt: skip
    else:
        text = f"not reached{plan}: {figures} in {_n(main.get('duration_s'))} s"
    h2h, ratio = main.get("hover_to_hover_s"), main.get("flown_over_optimum")
    if isinstance(h2h, int | float):
        text += f"; hover to hover {_n(h2h)} s" + (f", {_n(ratio)}× the optimum" if isinstance(ratio, int | float)
                                                   else "")  # fmt: skip
    return text + (f"; {main['note']}" if main.get("note") else "")
