"""``flighttest region chart|check``: the velocity-space chart and the guard's test, scriptable."""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np
import pandas as pd
from rich.table import Table

from flighttest import inputs as ip
from flighttest.console import console, print_json
from flighttest.errors import FlighttestError
from flighttest.model import aero
from flighttest.model.frames import validate_quaternion
from flighttest.model.profiles import load_profile

IN_COLUMNS = ["vn", "ve", "vd", "qw", "qx", "qy", "qz"]
WIND_COLUMNS = ["wn", "we", "wd"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("region", help="velocity-space chart and the VRS/WBS guard test")
    rsub = p.add_subparsers(dest="region_command", metavar="ACTION", required=True)

    pc = rsub.add_parser("chart", help="PNG of the normalised velocity space (paper Fig. 5/8)")
    pc.add_argument("--vehicle", required=True, help="profile name or .toml path")
    pc.add_argument("-o", "--output", default="chart.png",
                    help="figure to write: .png, .pdf or .svg (default chart.png)")
    pc.set_defaults(func=cmd_chart)

    pk = rsub.add_parser(
        "check",
        help="is a state allowed? (blade-frame, air-relative; as the live guard tests it)",
        description="Classify one state (--v-ned/--quat) or many (--csv with columns vn,ve,vd,qw,qx,qy,qz "
        "and optional wn,we,wd). Output adds verdict (allowed/forbidden), w, u and margin (m/s, ≥ 0 allowed).",
    )
    pk.add_argument("--vehicle", required=True, help="profile name or .toml path")
    one = pk.add_argument_group("one state")
    one.add_argument("--v-ned", nargs=3, type=ip.VELOCITY_MPS, metavar=("VN", "VE", "VD"), help="velocity NED, m/s")
    one.add_argument("--quat", nargs=4, type=ip.QUAT_COMPONENT, metavar=("W", "X", "Y", "Z"), help="attitude body→NED")
    one.add_argument("--wind-ned", nargs=3, type=ip.VELOCITY_MPS, metavar=("WN", "WE", "WD"), help="wind NED, m/s")
    pk.add_argument("--csv", metavar="FILE", help="many states from a CSV file")
    pk.add_argument("-o", "--output", metavar="FILE", help="write the CSV result here, not stdout")
    pk.add_argument("--w-allow", type=ip.W_ALLOW_MPS, metavar="MPS", help="override the profile's w_allow (m/s)")
    pk.add_argument("--margin", type=ip.MARGIN_MPS, metavar="MPS", help="override the profile's guard margin (m/s)")
    pk.add_argument("--json", action="store_true", help="machine-readable output")
    pk.set_defaults(func=cmd_check)


def cmd_chart(args: argparse.Namespace) -> int:
    from flighttest.model.chart import write_chart

    profile = load_profile(args.vehicle)
    out = ip.check_output_path(args.output, "-o/--output", ip.IMAGE_SUFFIXES)
    try:
        out = write_chart(profile, out)
    except OSError as exc:
        raise FlighttestError(f"-o/--output {out}: cannot write ({exc.strerror or exc})") from None
    console.print(f"wrote {out}")
    return 0


def _region_for(args: argparse.Namespace):
    profile = load_profile(args.vehicle)
    return profile, profile.guard_region(args.w_allow, args.margin)


def _finite_result(where: str, *values) -> None:
    """The guard's test must come out as numbers: a NaN margin would read as neither side."""
    for v in values:
        if not np.all(np.isfinite(v)):
            raise FlighttestError(f"{where}: the state gives a non-finite blade-frame velocity (inputs out of range)")


def cmd_check(args: argparse.Namespace) -> int:
    profile, region = _region_for(args)
    if args.output is not None:
        if args.csv is None:
            raise FlighttestError("-o/--output applies to --csv only")
        ip.check_output_path(args.output, "-o/--output")
    if args.csv is not None:
        if args.v_ned or args.quat or args.wind_ned:
            raise FlighttestError("give either --csv or --v-ned/--quat, not both")
        return _check_csv(args, profile, region)
    if args.v_ned is None or args.quat is None:
        raise FlighttestError("region check needs --v-ned VN VE VD and --quat W X Y Z, or --csv FILE")
    wind = args.wind_ned or [0.0, 0.0, 0.0]
    values = [*args.v_ned, *args.quat, *wind]
    if not all(math.isfinite(v) for v in values):
        raise FlighttestError("--v-ned, --quat and --wind-ned must be finite numbers")
    if not validate_quaternion(*args.quat):
        norm = math.sqrt(sum(c * c for c in args.quat))
        raise FlighttestError(f"--quat must be a unit quaternion (norm {norm:.6g})")
    allowed, w, u, margin = region.check(*args.v_ned, *args.quat, *wind)
    _finite_result("region check", w, u, margin)
    v_H_n, v_z_n = region.normalised(w, u)
    reg = aero.Region(int(aero.classify_n(v_H_n, v_z_n, profile.vrs.onera_k, profile.vrs.eps_vrs,
                                          profile.vrs.eps_tws, profile.vrs.cone_deg)))
    result = {
        "verdict": "allowed" if allowed else "forbidden",
        "w_mps": w,
        "u_mps": u,
        "margin_mps": margin,
        "v_H_n": v_H_n,
        "v_z_n": v_z_n,
        "region": reg.name,
        "w_allow_mps": region.w_allow_mps,
        "cone_deg": region.cone_deg,
        "guard_margin_mps": region.margin_mps,
    }
    if args.json:
        print_json(result)
    else:
        t = Table(title=f"{profile.name}: {result['verdict'].upper()}", show_header=False)
        t.add_column("quantity")
        t.add_column("value", justify="right")
        for k, v in result.items():
            t.add_row(k, f"{v:.4f}" if isinstance(v, float) else str(v))
        console.print(t)
    return 0


def _check_csv(args: argparse.Namespace, profile, region) -> int:
    path = ip.check_input_file(args.csv, "--csv", ip.MAX_CSV_BYTES)
    try:
        df = pd.read_csv(path, encoding="utf-8")
    except (OSError, ValueError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        why = " ".join(str(exc).split())[:120]
        raise FlighttestError(f"{args.csv}: not a readable CSV ({why})") from None
    df.columns = [str(c).strip() for c in df.columns]
    missing = [c for c in IN_COLUMNS if c not in df.columns]
    if missing:
        raise FlighttestError(f"{args.csv}: missing column(s) {', '.join(missing)} (need {','.join(IN_COLUMNS)})")
    partial_wind = [c for c in WIND_COLUMNS if c in df.columns]
    if partial_wind and len(partial_wind) != 3:
        raise FlighttestError(f"{args.csv}: wind needs all of wn,we,wd (found only {','.join(partial_wind)})")
    cols = IN_COLUMNS + (WIND_COLUMNS if partial_wind else [])
    arr = {}
    for c in cols:
        values = pd.to_numeric(df[c], errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raw = df[c].iloc[bad[0]]
            raise FlighttestError(f"{args.csv}: row {bad[0] + 2}, column '{c}': not a finite number ({ip.shown(raw)})")
        rng = ip.QUAT_COMPONENT if c.startswith("q") else ip.VELOCITY_MPS
        out_of_range = np.flatnonzero(~((values >= rng.lo) & (values <= rng.hi)))
        if out_of_range.size:
            i = out_of_range[0]
            raise FlighttestError(
                f"{args.csv}: row {i + 2}, column '{c}': must be {rng.describe()} (got {values[i]:g})"
            )
        arr[c] = values
    ok_q = validate_quaternion(arr["qw"], arr["qx"], arr["qy"], arr["qz"])
    if not ok_q.all():
        row = int(np.flatnonzero(~ok_q)[0])
        raise FlighttestError(f"{args.csv}: row {row + 2}: quaternion is not of unit norm")
    wind = [arr[c] for c in WIND_COLUMNS] if partial_wind else [0.0, 0.0, 0.0]
    allowed, w, u, margin = region.check(*(arr[c] for c in IN_COLUMNS), *wind)
    _finite_result(str(args.csv), w, u, margin)
    out = df.copy()
    out["verdict"] = np.where(allowed, "allowed", "forbidden")
    out["w"] = w
    out["u"] = u
    out["margin"] = margin
    if args.output is not None:
        try:
            with ip.atomic_write(args.output) as tmp:
                out.to_csv(tmp, index=False)
        except OSError as exc:
            raise FlighttestError(f"-o/--output {args.output}: cannot write ({exc.strerror or exc})") from None
        if args.json:
            print_json({"path": str(args.output), "n_states": len(out), "n_forbidden": int((~allowed).sum())})
        else:
            console.print(f"wrote {args.output}: {len(out)} states, {int((~allowed).sum())} forbidden")
    elif args.json:
        print_json(out.to_dict(orient="records"))
    else:
        out.to_csv(sys.stdout, index=False)
    return 0
