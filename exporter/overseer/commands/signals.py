"""How a long-running command waits for its end: SIGTERM or SIGINT, and a second one to leave at once.

SIGHUP, as every daemon takes it, asks to read the configuration that can change while running again.
The signals are caught from before the command starts its parts: a stop sent while it starts (systemd
stopping a service, to every process of its group) is kept for `StopSignals.wait`, not the default
action that would end the process with its parts half started.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
from collections.abc import Callable

log = logging.getLogger("overseer")


class StopSignals:
    """SIGTERM and SIGINT caught from its making on; SIGHUP too, for a command that reads its files again."""

    def __init__(self, on_hangup: Callable[[], object] | None = None) -> None:
        """Catch the signals now; with `on_hangup`, each SIGHUP calls it (from `wait`'s thread)."""
        self._stop = threading.Event()
        self._hangup = threading.Event()
        self._on_hangup = on_hangup
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, self._first)
        if on_hangup is not None:
            signal.signal(signal.SIGHUP, lambda _signum, _frame: self._hangup.set())

    def _first(self, signum: int, _frame: object) -> None:
        self._stop.set()
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, _again)

    def wait(self) -> None:
        """Return at SIGTERM or SIGINT (at once if one came already); then a second one ends the process."""
        while not self._stop.wait(0.2):
            if self._hangup.is_set():
                self._hangup.clear()
                log.info("SIGHUP: reading the inventory again")
                if self._on_hangup is not None:
                    self._on_hangup()
        log.info("stopping")


def _again(signum: int, _frame: object) -> None:
    log.warning("%s again while stopping: leaving at once", signal.Signals(signum).name)
    logging.shutdown()
    os._exit(128 + signum)
