"""The campaign's report: the descents side by side, the identified onset, the figures, one summary.

``report/summary.md`` is the table a person pastes into a flight-test report; ``summary.json`` holds the
same figures for scripts; ``compare.csv`` is ``flighttest compare`` of the two descents; ``report.md``
(with its PNGs) details every flight; ``velocity_space.png`` and ``descent_times.png`` compare them.
"""

from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path
from typing import Any

import pandas as pd

from flighttest import __version__
from flighttest.analysis import legend
from flighttest.analysis.compare import add_speedup, compare_row
from flighttest.analysis.descent_time import HOVER_RULE, DescentRule
from flighttest.campaign.state import STEPS, CampaignState
from flighttest.campaign.steps import BUDGET_KEY
from flighttest.errors import FlighttestError
from flighttest.flying.log_writer import write_json_atomic
from flighttest.model.profiles import VehicleProfile
from flighttest.planner.optimum import EFFICIENCY_KEYS

REPORT_FILES = ("summary.md", "summary.json", "compare.csv", "report.md", "velocity_space.png", "descent_times.png")
FLIGHTS = ("probe", "vertical", "helix")
DESCENTS = ("vertical", "helix")
ROWS = (  # the summary table, one column per descent: label, key, format (labels fit an 80-column line)
    ("outcome", "outcome", "{}"),
    ("descent time s (first setpoint → settled at the end)", "descent_time_s", "{:.2f}"),
    ("planned descent time s (the plan, same rule)", "planned_descent_s", "{:.2f}"),
    ("speed-up × (vertical / this)", "speedup_vs_vertical", "{:.2f}"),
    ("hover to hover s (settled at the end point)", "hover_to_hover_s", "{:.2f}"),
    ("optimum s (the planner's: margin 0, full limits)", "optimum_s", "{:.2f}"),
    ("flown / optimum × (hover to hover)", "flown_over_optimum", "{:.2f}"),
    ("horizontal error at that instant m", "horizontal_error_m", "{:.2f}"),
    ("start height m (above the ground)", "start_height_m", "{:.2f}"),
    ("height m", "height_m", "{:.2f}"),
    ("mean descent rate m/s", "mean_rate_mps", "{:.2f}"),
    ("max descent rate m/s", "max_rate_mps", "{:.2f}"),
    ("horizontal excursion m", "horizontal_excursion_m", "{:.2f}"),
    ("inside the guard region s", "time_inside_s", "{:.2f}"),
    ("near its boundary s", "time_near_s", "{:.2f}"),
    ("min margin to it m/s", "min_margin_mps", "{:.3f}"),
    ("inside at the worst air within the wind's uncertainty s", "time_inside_worst_s", "{:.2f}"),
    ("wind m/s (over the descent)", "wind_speed_mps", "{:.2f}"),
    ("wind 1 σ m/s", "wind_sd_mps", "{:.2f}"),
    ("wind from", "wind_source", "{}"),
    ("guard aborts", "guard_aborts", "{}"),
)


def cell(row: dict[str, Any], key: str, fmt: str) -> str:
    v = row.get(key)
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return fmt.format(v)


def campaign_summary(state: CampaignState, profile: VehicleProfile, rows: dict[str, dict[str, Any]]) -> dict:
    """Everything the summary says, as JSON-able data (also what ``flighttest campaign --json`` prints)."""
    ident = state.steps["identify"].outputs
    vert, helix = rows.get("vertical", {}), rows.get("helix", {})
    found = ident.get("onset_found", ident.get("w_onset_mps") is not None if ident else None)  # older records
    profile_path, probe_log = state.maybe_path("identify", "profile"), state.maybe_path("probe", "log_dir")
    return {
        "vehicle": profile.name,
        "v_h_mps": profile.v_h_mps,
        "out_dir": str(state.dir.root),
        "identified_w_allow_mps": ident.get("w_onset_mps"),
        "identified_uncertainty_mps": ident.get("uncertainty_mps"),
        "prior_w_allow_mps": ident.get("prior_w_allow_mps"),
        # false: the probe stayed quiet up to the lower bound and the flights used the prior w_allow
        "onset_found": found,
        "w_onset_lower_bound_mps": ident.get("w_onset_lower_bound_mps"),
        # what identify said where it kept the prior (no onset, or an onset it did not trust)
        "identify_message": ident.get("message"),
        "identified_profile": str(profile_path) if profile_path else None,
        "vertical_descent_s": vert.get("descent_time_s"),
        "helix_descent_s": helix.get("descent_time_s"),
        "speedup_helix_vs_vertical": helix.get("speedup_vs_vertical"),
        "vertical_hover_to_hover_s": vert.get("hover_to_hover_s"),
        "helix_hover_to_hover_s": helix.get("hover_to_hover_s"),
        "vertical_flown_over_optimum": vert.get("flown_over_optimum"),
        "helix_flown_over_optimum": helix.get("flown_over_optimum"),
        "flights": [rows[s] for s in DESCENTS if s in rows],
        # each descent's build-up, flight by flight (campaign --build-up N), and why it stopped
        "build_up": {d: state.steps[d].outputs.get("build_up") or [] for d in DESCENTS},
        "build_up_stop": {d: state.steps[d].outputs.get("build_up_stop") for d in DESCENTS},
        # the margin each kept flight was planned with and its terms (flighttest.campaign.build_up)
        "margin_budget": {d: margin_budget(state, d) for d in DESCENTS},
        "probe_log": str(probe_log) if probe_log else None,
        "steps_elapsed_s": {s: state.steps[s].elapsed_s for s in STEPS},
        "report": str(state.dir.report),
        "flighttest_version": __version__,
    }


def margin_budget(state: CampaignState, descent: str) -> dict[str, Any] | None:
    """The margin budget of the flight the campaign kept: the step's (a build-up), else its plan's."""
    kept = state.steps[descent].outputs.get(BUDGET_KEY)
    if kept:
        return kept
    plan = state.maybe_path("plan", descent)
    if plan is None:
        return None
    try:
        meta = json.loads(Path(plan).with_suffix(".json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return meta.get(BUDGET_KEY) if isinstance(meta, dict) else None


BUILD_UP_COLUMNS = (  # the report's build-up table: header, key, format
    ("flight", "flight", "{}"), ("margin m/s", "margin_mps", "{:.3f}"), ("outcome", "outcome", "{}"),
    ("hover→hover s", "hover_to_hover_s", "{:.2f}"), ("÷ optimum", "flown_over_optimum", "{:.2f}"),
    ("plan's least margin m/s", "plan_min_margin_mps", "{:.3f}"), ("guard's least m/s", "min_margin_mps", "{:.3f}"),
    ("to acting m/s", "min_acting_margin_mps", "{:.3f}"),
    ("used m/s", "used_mps", "{:.3f}"),
    ("estimate error m/s", "estimate_mps", "{:.3f}"), ("guard silent", "guard_silent", "{}"),
)  # fmt: skip


def build_up_markdown(summary: dict) -> list[str]:
    """The report's build-up section, a table per descent and why each stopped; none without a build-up."""
    build_up = summary.get("build_up") or {}
    if not any(len(build_up.get(d) or []) > 1 for d in DESCENTS):
        return []
    lines = ["", "## Build-up", "",
             "Each flight after the first was planned with the margin what the earlier ones proved allows "
             "(`flighttest.campaign.build_up`); the campaign keeps the fastest that completed with the guard silent.",
             "", "![build-up](build_up.png)"]  # fmt: skip
    for d in DESCENTS:
        rows = build_up.get(d) or []
        if not rows:
            continue
        lines += ["", f"### {d}", "", "| " + " | ".join(h for h, _, _ in BUILD_UP_COLUMNS) + " |",
                  "|" + "---:|" * len(BUILD_UP_COLUMNS)]  # fmt: skip
        lines += ["| " + " | ".join(cell(r, k, f) for _, k, f in BUILD_UP_COLUMNS) + " |" for r in rows]
        stop = (summary.get("build_up_stop") or {}).get(d)
        if stop:
            lines += ["", f"Stopped: {stop}."]
    return lines


def budget_markdown(summary: dict) -> list[str]:
    """Each kept flight's margin and the terms it is made of, with where each came from."""
    out: list[str] = []
    for d in DESCENTS:
        b = (summary.get("margin_budget") or {}).get(d)
        if not b:
            continue
        out.append(f"- {d}: `{b['key']}` {b['margin_mps']:.3f} m/s ({b.get('note') or 'the terms summed'})")
        out += [f"  - {t['name']} {t['value_mps']:.3f} m/s: {t['source']}" for t in b.get("terms", ())]
    return ["", "## Margins", "", *out] if out else []


def known_summary(state: CampaignState, profile: VehicleProfile) -> dict[str, Any]:
    """The summary's keys filled from what ``campaign.json`` knows so far, analysing no log (a stop can
    come before any flight): what ``campaign --json`` prints when it ends before the report, with each
    step's status under ``steps``. Flights carry their step's outputs, not the compare columns."""
    rows: dict[str, dict[str, Any]] = {}
    for step in DESCENTS:
        o = state.steps[step].outputs
        if o:
            rows[step] = {"step": step, "status": state.steps[step].status, "outcome": o.get("outcome"),
                          "guard_aborts": o.get("guard_aborts"), "descent_time_s": o.get("descent_time_s"),
                          "planned_descent_s": o.get("planned_descent_s"),
                          "horizontal_error_m": o.get("horizontal_error_m"), "log_dir": o.get("log_dir"),
                          **{k: o.get(k) for k in EFFICIENCY_KEYS}}  # fmt: skip
    t_v, t_h = (rows.get(d, {}).get("descent_time_s") for d in DESCENTS)
    if isinstance(t_v, int | float) and isinstance(t_h, int | float) and t_h > 0:
        rows["helix"]["speedup_vs_vertical"] = t_v / t_h
    out = campaign_summary(state, profile, rows)
    out["report"] = str(state.dir.report) if state.done("report") else None
    out["steps"] = {s: state.steps[s].status for s in STEPS}
    return out


def headlines(s: dict) -> list[str]:
    """The two sentences a flight-test report opens with: the onset found (or how far the probe went
    without one, and the prior the flights used), and the time saved."""
    onset_n = s["identified_w_allow_mps"] / s["v_h_mps"] if s["identified_w_allow_mps"] else None
    bound = s.get("w_onset_lower_bound_mps")
    if s.get("onset_found") is False and bound is not None:
        first = (f"no onset found up to {bound:.2f} m/s ({bound / s['v_h_mps']:.3f} v_h; v_h {s['v_h_mps']:.2f} m/s): "
                 f"w_allow kept at the prior {cell(s, 'prior_w_allow_mps', '{:.3f}')} m/s, which the plans and "
                 "the guard used")  # fmt: skip
    elif s.get("onset_found") is False and s.get("identify_message"):
        first = f"{s['identify_message']}; the plans and the guard used the prior"
    else:
        first = (f"VRS onset from the probe: {cell(s, 'identified_w_allow_mps', '{:.3f}')} ± "
                 f"{cell(s, 'identified_uncertainty_mps', '{:.3f}')} m/s "
                 f"({cell({'n': onset_n}, 'n', '{:.3f}')} v_h; v_h {s['v_h_mps']:.2f} m/s; "
                 f"the profile said {cell(s, 'prior_w_allow_mps', '{:.3f}')} m/s)")  # fmt: skip
    helix = next((f for f in s.get("flights", []) if f.get("step") == "helix"), {})
    times = (f"the helix took {cell(s, 'helix_descent_s', '{:.2f}')} s against the vertical baseline's "
             f"{cell(s, 'vertical_descent_s', '{:.2f}')} s")  # fmt: skip
    if helix.get("descent_differs"):
        second = f"{times}, but no speed-up: the helix {helix['descent_differs']} (the vertical baseline's)"
    else:
        second = f"over the same height {times}: {cell(s, 'speedup_helix_vs_vertical', '{:.2f}')}× as fast"
    if s.get("vertical_flown_over_optimum") is not None or s.get("helix_flown_over_optimum") is not None:
        second += (f"; hover to hover the helix took {cell(s, 'helix_flown_over_optimum', '{:.2f}')}× its optimum, "
                   f"the vertical {cell(s, 'vertical_flown_over_optimum', '{:.2f}')}× its own")  # fmt: skip
    return [first, second]


def table_rows(s: dict) -> list[tuple[str, str, str]]:
    """(quantity, vertical, helix) rows of the summary table."""
    flights = {f["step"]: f for f in s["flights"]}
    return [(label, *(cell(flights.get(d, {}), key, fmt) for d in DESCENTS)) for label, key, fmt in ROWS]


ROW_LEGEND = {  # summary-table key: the legend's header for it (flighttest.analysis.legend.COLUMNS)
    "descent_time_s": "descent s", "planned_descent_s": "planned s", "speedup_vs_vertical": "speed-up ×",
    "horizontal_error_m": "horiz. err m", "start_height_m": "start m", "max_rate_mps": "max m/s",
    "horizontal_excursion_m": "horiz. m", "time_inside_s": "inside s", "time_near_s": "near s",
    "min_margin_mps": "min margin m/s", "time_inside_worst_s": "inside, worst air s", "wind_speed_mps": "wind m/s",
}  # fmt: skip


def row_legend() -> list[tuple[str, str]]:
    """(row label, what it means) for the summary table's rows that need more than their label."""
    out = [(label, legend.COLUMNS[ROW_LEGEND[key]]) for label, key, _ in ROWS if key in ROW_LEGEND]
    out += [("wind 1 σ m/s", "the uncertainty of that wind"),
            ("wind from", "what flighttest flew with, else the autopilot's estimate, else flighttest's estimate "
             "from the IMU and the drag model (`flighttest.analysis.wind`)"),
            ("guard aborts", "the live guard's abort orders in the flight (`guard.csv`)"),
            ("hover to hover s", f"from the first setpoint until {HOVER_RULE.describe()}"),
            ("optimum s", "the planner's fastest descent for this vehicle, height, radius, end point and wind, with "
             "no guard margin and the vehicle's and its autopilot's full limits, timed by the same rule "
             "(`flighttest.planner.optimum`)")]  # fmt: skip
    return out


def summary_markdown(summary: dict) -> str:
    lines = [
        f"# Fast-descent campaign: {summary['vehicle']}",
        "",
        *(f"- {h}" for h in headlines(summary)),
        "",
        "| | vertical baseline | helix |",
        "|---|---:|---:|",
    ]
    lines += [f"| {q} | {v} | {h} |" for q, v, h in table_rows(summary)]
    notes = []
    for f in summary["flights"]:
        if f.get("abort_reason"):
            notes.append(f"- {f['step']}: {f.get('outcome')}: {f['abort_reason']}")
        if f.get("main_descent_note"):
            notes.append(f"- {f['step']}: {f['main_descent_note']}")
        if f.get("descent_differs"):
            notes.append(f"- {f['step']}: {f['descent_differs']} (the vertical baseline's)")
        if f.get("judged_with"):
            notes.append(f"- {f['step']} judged with {legend.judged_text(f['judged_with'])}")
    lines += ["", *notes] if notes else []
    lines += [
        "",
        "The main descent of each flight is one descent, whatever phases it crossed: from the first setpoint of the",
        "planned descent until the vehicle is at its end point's height with its vertical speed settled",
        f"({DescentRule().describe()}; the vertical axis only: the horizontal",
        "error at that instant is in the table). `flighttest fly`, `analyse`, `compare` and `report` give the same.",
        "",
        *(f"- {label}: {text}" for label, text in row_legend()),
        "",
        *budget_markdown(summary),
        *build_up_markdown(summary),
        "",
        "Every flight in detail, its plan under its flown path, the probe's fluctuation plot with the onset:",
        "[report.md](report.md).",
        "",
        "![velocity space](velocity_space.png)",
        "",
        "![descent times](descent_times.png)",
        "",
    ]
    return "\n".join(lines)


def write_campaign_report(state: CampaignState, profile: VehicleProfile) -> dict[str, Any]:
    """Analyse the campaign's flights and write every file of ``REPORT_FILES`` into ``DIR/report``."""
    from flighttest.analysis.batch import quiet_numerics

    with quiet_numerics():  # numpy's and matplotlib's warnings about absent streams: nothing for the user
        return _write_campaign_report(state, profile)


def _write_campaign_report(state: CampaignState, profile: VehicleProfile) -> dict[str, Any]:
    from flighttest.analysis.identify import ImplausibleOnset, NoOnset, identify_onset
    from flighttest.analysis.loaders import load_log
    from flighttest.analysis.pipeline import analyse
    from flighttest.analysis.report import write_report
    from flighttest.campaign.figures import plot_build_up, plot_descent_comparison, plot_tracks_velocity_space

    out_dir = state.dir.report
    out_dir.mkdir(parents=True, exist_ok=True)
    analyses, rows = {}, {}
    for step in FLIGHTS:
        log_dir = state.maybe_path(step, "log_dir")
        if log_dir is None:
            continue
        # each flight judged with the profile it flew with (the probe with the prior, the descents with
        # the identified w_allow), the campaign's profile only for a flight whose log does not say
        a = analyse(load_log(log_dir))
        if a.profile is None:
            a = analyse(load_log(log_dir), profile.path)
        analyses[step] = a
        o = state.steps[step].outputs
        row = compare_row(str(log_dir), a.descents, a.log.events, a.log.meta, main=a.main)
        rows[step] = {"step": step, **row, "outcome": o.get("outcome", row.get("outcome")),
                      "guard_aborts": o.get("guard_aborts"), "judged_with": a.judged_with}  # fmt: skip
    if "vertical" not in analyses or "helix" not in analyses:
        raise FlighttestError("the report needs both the vertical and the helix flight")
    for row in add_speedup([rows["vertical"], rows["helix"]], key="descent_time_s"):
        row["speedup_vs_vertical"] = row.pop("speedup_vs_first")
    pd.DataFrame([{k: v for k, v in rows[s].items() if k != "judged_with"} for s in DESCENTS]).to_csv(
        out_dir / "compare.csv", index=False
    )
    onsets = {}
    if "probe" in analyses:
        # no onset, or one not trusted: the probe's plot says "no onset identified", the summary that the
        # prior was kept
        with contextlib.suppress(NoOnset, ImplausibleOnset):
            onsets[str(analyses["probe"].log.path)] = identify_onset(analyses["probe"].log, profile)
    write_report(list(analyses.values()), out_dir, onsets)
    plot_tracks_velocity_space(analyses["vertical"], analyses["helix"], out_dir / "velocity_space.png",
                               probe=analyses.get("probe"))  # fmt: skip
    plot_descent_comparison(analyses["vertical"], analyses["helix"], out_dir / "descent_times.png")
    summary = campaign_summary(state, profile, rows)
    if any(len(summary["build_up"][d]) > 1 for d in DESCENTS):
        plot_build_up(summary["build_up"], out_dir / "build_up.png")
    write_json_atomic(out_dir / "summary.json", summary)
    (out_dir / "summary.md").write_text(summary_markdown(summary), encoding="utf-8")
    return {"report_dir": str(out_dir), "files": [str(out_dir / f) for f in REPORT_FILES],
            "speedup_helix_vs_vertical": summary["speedup_helix_vs_vertical"]}  # fmt: skip


def read_summary(report_dir: Path) -> dict[str, Any]:
    path = report_dir / "summary.json"
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise FlighttestError(f"{path}: cannot read the campaign summary ({exc})") from None
