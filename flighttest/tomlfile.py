"""Reading the project's TOML files (profiles, mission configs) with one-line errors."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from flighttest.errors import FlighttestError


def read_toml(path: Path | str, what: str) -> dict[str, Any]:
    """Parsed TOML of ``path``; unreadable or malformed files raise one FlighttestError line."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise FlighttestError(f"{path}: cannot read {what} ({exc.strerror})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FlighttestError(f"{path}: malformed TOML ({exc})") from None
