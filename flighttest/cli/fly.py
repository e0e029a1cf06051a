"""`flighttest fly` commands (placeholder until its capability lands)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    return None
