"""The `overseer` commands, a module each: its arguments, and what it does with them.

Each module's `COMMAND` is what `cli.py` lists; a new command is a module here and a line there.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class Command:
    """One `overseer` command: its name, its help, its arguments, and what it runs (an exit status)."""

    name: str
    help: str
    description: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]
