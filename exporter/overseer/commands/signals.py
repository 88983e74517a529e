"""How a long-running command waits for its end: SIGTERM or SIGINT, and a second one to leave at once."""

from __future__ import annotations

import logging
import os
import signal
import threading

log = logging.getLogger("overseer")


def wait_for_signal() -> None:
    """Return at SIGTERM or SIGINT; from then on a second one ends the process at once."""
    stop = threading.Event()

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
    while not stop.wait(1.0):
        pass
    log.info("stopping")
