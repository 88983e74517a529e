"""How a long-running command waits for its end: SIGTERM or SIGINT, and a second one to leave at once.

SIGHUP, as every daemon takes it, asks to read the configuration that can change while running again.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
from collections.abc import Callable

log = logging.getLogger("overseer")


def wait_for_signal(on_hangup: Callable[[], object] | None = None) -> None:
    """Return at SIGTERM or SIGINT; from then on a second one ends the process at once.

    With `on_hangup`, each SIGHUP calls it (from this thread, not the signal handler).
    """
    stop = threading.Event()
    hangup = threading.Event()

    def first(signum: int, _frame: object) -> None:
        stop.set()
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, again)

    def again(signum: int, _frame: object) -> None:
        log.warning("%s again while stopping: leaving at once", signal.Signals(signum).name)
        logging.shutdown()
        os._exit(128 + signum)

    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, first)
    if on_hangup is not None:
        signal.signal(signal.SIGHUP, lambda _signum, _frame: hangup.set())
    while not stop.wait(0.2):
        if hangup.is_set():
            hangup.clear()
            log.info("SIGHUP: reading the inventory again")
            if on_hangup is not None:
                on_hangup()
    log.info("stopping")
