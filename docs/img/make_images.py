"""Regenerate every image in docs/img from one fresh campaign on the built-in fake.

    .venv/bin/python docs/img/make_images.py            # a new campaign in a temporary folder
    .venv/bin/python docs/img/make_images.py -o DIR     # ... kept in DIR (an existing one is resumed)

It runs what the README's first command runs (``flighttest campaign --sim --yes -o DIR``), copies the
report's figures over the README's (``IMAGES``), and prints the campaign's summary table, so the
README's excerpt of it can be set to the numbers of the same run as the figures. The script lives
beside the images it makes: one place to look when a figure changes.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
# report file of the campaign -> image in docs/img the README shows
IMAGES = {
    "report/velocity_space.png": "campaign_velocity_space.png",
    "report/descent_times.png": "campaign_descent_times.png",
}


def run_campaign(out: Path) -> None:
    """``flighttest campaign --sim --yes -o out`` from this checkout, its progress on the console."""
    cmd = [sys.executable, "-m", "flighttest", "campaign", "--sim", "--yes", "-o", str(out)]
    print("$ " + " ".join(cmd[1:]), flush=True)
    proc = subprocess.run(cmd, cwd=ROOT)
    if proc.returncode != 0:
        sys.exit(f"make_images: the campaign failed (exit {proc.returncode}); the images were left as they were")


def copy_images(out: Path) -> list[Path]:
    missing = [src for src in IMAGES if not (out / src).is_file()]
    if missing:
        sys.exit(f"make_images: {out} has no {', '.join(missing)}; the images were left as they were")
    written = []
    for src, name in IMAGES.items():
        shutil.copyfile(out / src, HERE / name)
        written.append(HERE / name)
    return written


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("-o", "--output", type=Path, metavar="DIR", help="the campaign's folder (default: a temporary one)")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="flighttest-images-") as tmp:
        out = args.output or Path(tmp) / "campaign"
        run_campaign(out.resolve())
        for path in copy_images(out):
            print(f"wrote {path.relative_to(ROOT)}")
        summary = json.loads((out / "report" / "summary.json").read_text(encoding="utf-8"))
        print(f"\nREADME excerpt ({summary['vehicle']}; flighttest {summary.get('flighttest_version')}):\n")
        print((out / "report" / "summary.md").read_text(encoding="utf-8"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
