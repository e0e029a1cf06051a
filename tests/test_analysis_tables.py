"""Tables that fit the terminal: at 80 columns `analyse` and `compare` show fewer columns or stack them,
with full headers and values — never rich's cut "sta…", "2.…"; `--wide` and wide terminals show everything."""

from __future__ import annotations

import json
import os

import pandas as pd
import pytest
from rich.console import Console

import flighttest.cli.analysis as cli
from flighttest.analysis.compare import add_param_differences, add_speedup, compare_row

ALL_HEADERS = list(cli.DESCENT_COLUMNS)


def _descents(n: int = 3) -> pd.DataFrame:
    rows = []
    for k in range(n):
        rows.append({
            "descent": k + 1, "start_s": 1234.56 + 10 * k, "duration_s": 12.345, "height_m": 15.25,
            "mean_rate_mps": 1.2345, "max_rate_mps": 2.3456, "horizontal_excursion_m": 0.5, "time_inside_s": 0.0,
            "time_near_s": 1.25, "min_margin_mps": -0.123, "fluct_index_max": 12.3, "phase": "stream",
        })  # fmt: skip
    return pd.DataFrame(rows)


def _render(monkeypatch, width: int, build) -> str:
    con = Console(width=width, record=True, file=open(os.devnull, "w"))  # noqa: SIM115 (closed with the console)
    monkeypatch.setattr(cli, "console", con)
    cli._print_all(build())
    con.file.close()
    return con.export_text()


def _lines_fit(text: str, width: int) -> bool:
    return all(len(line.rstrip()) <= width for line in text.splitlines())


def test_analyse_table_at_80_columns_keeps_the_essentials_whole(monkeypatch):
    text = _render(monkeypatch, 80, lambda: cli.descent_tables("/logs/20261201-101530-vertical (tlog)", _descents()))
    assert "…" not in text and _lines_fit(text, 80)
    for header in cli.DESCENT_ESSENTIALS:
        assert f" {header} " in text
    assert "1234.56" in text and "12.35" in text and "stream" in text
    assert "min margin m/s" not in text and "--wide" in text


def test_analyse_table_wide_terminal_and_wide_flag_show_every_column(monkeypatch):
    text = _render(monkeypatch, 200, lambda: cli.descent_tables("log", _descents()))
    assert "…" not in text and all(f" {h} " in text for h in ALL_HEADERS) and "--wide" not in text
    text = _render(monkeypatch, 80, lambda: cli.descent_tables("log", _descents(), wide=True))
    assert "…" not in text and all(f" {h} " in text for h in ALL_HEADERS) and "-0.12" in text


def test_analyse_table_stacks_on_a_very_narrow_terminal(monkeypatch):
    text = _render(monkeypatch, 40, lambda: cli.descent_tables("a-long-log-name.tlog (tlog, 30.0 s)", _descents(5)))
    assert "…" not in text and _lines_fit(text, 40)
    for header in ALL_HEADERS[1:]:
        assert f" {header} " in text  # every column, as a row with its full header
    assert all(f"#{k}" in text for k in range(1, 6))
    assert text.count("1234.56") == 1 and "a-long-log-name.tlog" in text
    empty = _render(monkeypatch, 80, lambda: cli.descent_tables("log", _descents(0)))
    assert "…" not in empty and " duration s " in empty


def _rows(names, params=None):
    d = _descents(1)
    d["mission"], d["trajectory"], d["time_vrs_s"] = "helix", "helix", 0.0
    rows = [
        compare_row(f"/logs/{n}", d, [], {"summary": {"outcome": "completed"}}, (params or [{}] * len(names))[i])
        for i, n in enumerate(names)
    ]
    add_speedup(rows)
    return add_param_differences(rows)


LONG = ["20261201-101530-vertical_descent-rehearsal", "20261201-103012-helix_descent-rehearsal-2"]


def test_compare_at_80_columns_with_long_folder_names(monkeypatch):
    rows = _rows(LONG)
    text = _render(monkeypatch, 80, lambda: cli.compare_tables(rows))
    assert "…" not in text and _lines_fit(text, 80)
    assert all(name in text for name in LONG)  # in the legend, whole
    for header in cli.COMPARE_COLUMNS:
        assert f" {header} " in text
    assert "completed" in text
    wide = _render(monkeypatch, 80, lambda: cli.compare_tables(rows, wide=True))
    assert "…" not in wide and all(name in wide for name in LONG) and " min margin m/s " in wide
    text = _render(monkeypatch, 270, lambda: cli.compare_tables(rows))
    assert "…" not in text and all(f" {h} " in text for h in ["log", "mission", *cli.COMPARE_COLUMNS])


def test_compare_short_names_are_the_column_headers(monkeypatch):
    text = _render(monkeypatch, 80, lambda: cli.compare_tables(_rows(["vertical", "helix"])))
    assert "…" not in text and " vertical " in text and "  1: " not in text


def test_compare_parameter_differences_fit(monkeypatch):
    base = {"MPC_Z_VEL_MAX_DN": 1.5, "MC_ROLL_P": 6.5, "MPC_XY_VEL_P_ACC": 1.8}
    params = [base, {**base, "MPC_Z_VEL_MAX_DN": 2.0, "MPC_LAND_SPEED": 0.7}]
    text = _render(monkeypatch, 80, lambda: cli.compare_tables(_rows(LONG, params)))
    assert "…" not in text and _lines_fit(text, 80)
    assert "parameters that differ between the flights (2)" in text
    assert " MPC_Z_VEL_MAX_DN " in text and " MPC_LAND_SPEED " in text and " MC_ROLL_P " not in text
    assert "2" in text and "0.7" in text
    same = _render(monkeypatch, 80, lambda: cli.compare_tables(_rows(LONG, [base, dict(base)])))
    assert "set up alike" in same
    none = _render(monkeypatch, 80, lambda: cli.compare_tables(_rows(LONG)))
    assert "0 of 2 logs carry them" in none


@pytest.mark.parametrize("columns", [80, 200])
def test_analyse_command_at_that_width(tmp_path, monkeypatch, capsys, columns):
    """The command itself (in-process, its console that wide); --json and --csv do not depend on it."""
    from flighttest.cli import main
    from synthetic import SyntheticFlight, write_tlog

    log = write_tlog(
        SyntheticFlight(duration_s=20.0, descents=[(5.0, 3.0, 2.0), (12.0, 4.0, 2.5)]), tmp_path / "f.tlog"
    )
    con = Console(width=columns, record=True, file=open(os.devnull, "w"))  # noqa: SIM115 (closed below)
    monkeypatch.setattr(cli, "console", con)
    csv = tmp_path / "d.csv"
    assert main(["analyse", str(log), "--vehicle", "x500", "--jobs", "1", "--csv", str(csv)]) == 0
    con.file.close()
    text = con.export_text()
    assert "…" not in text and _lines_fit(text, columns)
    shown = cli.DESCENT_ESSENTIALS if columns < 100 else ALL_HEADERS
    assert all(f" {h} " in text for h in shown)
    assert (" min margin m/s " in text) == (columns >= 130)
    table = pd.read_csv(csv)
    assert len(table) == 2 and {"min_margin_mps", "fluct_index_max", "phase", "duration_s"} <= set(table.columns)
    capsys.readouterr()
    assert main(["analyse", str(log), "--json", "--jobs", "1"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert isinstance(data, list) and len(data[0]["descents"]) == 2
