"""The expiry timer: forgets robots and components silent for `expire_after`, from a thread of its own."""

from __future__ import annotations

import logging
import threading

from overseer.model.fleet import FleetModel

log = logging.getLogger(__name__)

MIN_EXPIRY_INTERVAL_SECONDS = 1.0
MAX_EXPIRY_INTERVAL_SECONDS = 60.0
EXPIRY_LATENESS = 0.01  # how late forgetting may be, as a share of expire_after


def expiry_interval(expire_after: float) -> float:
    """How often to look for what to forget: at most 1 % of `expire_after` late, from 1 s to a minute.

    A look goes through every component of the fleet under the model's lock (150,000 at 3,000 robots):
    once a second it was a quarter of the exporter's CPU, to forget what had been silent for a week.
    """
    scaled = expire_after * EXPIRY_LATENESS
    return min(MAX_EXPIRY_INTERVAL_SECONDS, max(MIN_EXPIRY_INTERVAL_SECONDS, scaled))


def start_expiry(model: FleetModel, stopping: threading.Event) -> threading.Thread:
    """Expire `model` every `expiry_interval` until `stopping` is set; the thread is started."""

    def expire_loop() -> None:
        while not stopping.wait(expiry_interval(model.limits.expire_after)):
            for robot in model.expire():
                log.info("forgot robot %s after %gs of silence", robot, model.limits.expire_after)

    thread = threading.Thread(target=expire_loop, name="expiry", daemon=True)
    thread.start()
    return thread
