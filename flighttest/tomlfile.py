"""Reading the project's TOML files (profiles, mission configs) with one-line errors."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from flighttest.errors import FlighttestError
from flighttest.inputs import MAX_TOML_BYTES, InputFileError, read_text_file


def read_toml(path: Path | str, what: str) -> dict[str, Any]:
    """Parsed TOML of ``path``. A missing, unreadable, special (FIFO, device), oversized, non-UTF-8
    (binary, UTF-16, Latin-1), malformed or absurdly nested file raises one FlighttestError line."""
    try:
        text = read_text_file(path, what, MAX_TOML_BYTES)
    except InputFileError as exc:
        raise FlighttestError(f"{exc.path or path}: cannot read {what} ({exc.reason})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FlighttestError(f"{path}: malformed TOML ({exc})") from None
    except RecursionError:  # tomllib recurses once per nesting level: [[[[…]]]] exhausts the stack
        raise FlighttestError(f"{path}: malformed TOML (nested too deeply)") from None
    except ValueError as exc:  # e.g. an integer with more digits than Python converts
        raise FlighttestError(f"{path}: malformed TOML ({str(exc).splitlines()[0]})") from None
