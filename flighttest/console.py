"""Rich console and ``--json`` output shared by every command."""

from __future__ import annotations

import json
import math
import sys
from typing import Any

from rich.console import Console

console = Console()
err_console = Console(stderr=True)


def json_safe(obj: Any) -> Any:
    """JSON-safe copy: numpy scalars to Python, non-finite floats to null."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


json_printed = False  # set once a command printed its JSON: the CLI's {"error"} must not follow it


def print_json(data: Any) -> None:
    """Machine-readable output: plain JSON on stdout, nothing else."""
    global json_printed
    sys.stdout.write(json.dumps(json_safe(data), indent=2) + "\n")
    sys.stdout.flush()
    json_printed = True
