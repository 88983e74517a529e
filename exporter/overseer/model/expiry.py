"""The expiry timer: forgets robots and components silent for `expire_after`, from a thread of its own."""

from __future__ import annotations

import logging
import threading

from overseer.model.fleet import FleetModel

log = logging.getLogger(__name__)

EXPIRY_INTERVAL_SECONDS = 1.0


def start_expiry(model: FleetModel, stopping: threading.Event) -> threading.Thread:
    """Expire `model` every `EXPIRY_INTERVAL_SECONDS` until `stopping` is set; the thread is started."""

    def expire_loop() -> None:
        while not stopping.wait(EXPIRY_INTERVAL_SECONDS):
            for robot in model.expire():
                log.info("forgot robot %s after %gs of silence", robot, model.limits.expire_after)

    thread = threading.Thread(target=expire_loop, name="expiry", daemon=True)
    thread.start()
    return thread
