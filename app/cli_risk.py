"""``scengen`` sub-commands of this group (see app/cli.py for the conventions)."""

from __future__ import annotations

import argparse
from typing import Any


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add this group's sub-commands. Nothing here yet."""
