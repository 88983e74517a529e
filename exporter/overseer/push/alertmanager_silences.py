"""Maintenance windows as Alertmanager silences: one per window, expired when the window ends early.

A silence matches `robot="<name>"`, or `robot=~"<prefix>.*"` for a namespace, from the window's start
to its end, with the window's author and comment. Its id is kept beside the window in the exporter's
database, so a restarted exporter still knows it. Every `resync_interval` (and at once after a change)
the loop compares what Alertmanager holds with the windows: a silence that is missing (an Alertmanager
that lost its data) is made again, one an operator expired there is left expired. When Alertmanager cannot be
reached, the loop retries with a growing pause and counts the failures.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from collections.abc import Callable
from typing import Any

from overseer.clock import steady_time
from overseer.config.alertmanager import AlertmanagerConfig
from overseer.maintenance.effects import CREATED, REMOVED, EffectStats
from overseer.maintenance.schedule import MaintenanceSchedule
from overseer.model.maintenance import Window
from overseer.push.alertmanager_client import AlertmanagerClient, AlertmanagerError
from overseer.push.retry import BACKOFF_MAX, Retry

log = logging.getLogger(__name__)

TARGET = "alertmanager"
TICK_SECONDS = 0.5


class AlertmanagerSilences:
    """Keeps one Alertmanager silence per maintenance window of `schedule` that has not ended."""

    def __init__(
        self,
        config: AlertmanagerConfig,
        schedule: MaintenanceSchedule,
        stats: EffectStats | None = None,
        clock: Callable[[], float] = steady_time,
    ) -> None:
        """Silence in the Alertmanager of `config`; nothing is sent before `start`."""
        self._config = config
        self._schedule = schedule
        self.stats = stats or EffectStats(TARGET)
        self._clock = clock
        self._client = AlertmanagerClient(config)
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self._synced_revision = -1
        self._verify_at = 0.0
        self._retry = Retry("Alertmanager silences", log)

    def start(self) -> None:
        """Run the loop in a daemon thread."""
        self._thread = threading.Thread(target=self._run, name="alertmanager-silences", daemon=True)
        self._thread.start()
        log.info("maintenance windows silence alerts in Alertmanager at %s", self._config.url)

    def stop(self) -> None:
        """Stop the loop (a request under way ends within the timeout)."""
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout=self._config.timeout + 5)

    def _run(self) -> None:
        while not self._stopping.is_set():
            now = self._clock()
            due = self._schedule.revision != self._synced_revision or now >= self._verify_at
            if due and self._retry.due(now):
                try:
                    self.sync(now)
                except Exception:  # never take the exporter down; try again after a pause
                    log.exception("Alertmanager silences: unexpected error")
                    self._retry.pause(now + BACKOFF_MAX)
            self._stopping.wait(TICK_SECONDS)

    def sync(self, now: float) -> None:
        """Make the silences that are missing and expire those of windows ended early; retry on failure."""
        revision = self._schedule.revision
        windows = {window.key: window for window in self._schedule.windows(now)}
        made = {key: reference for (key, _), reference in self._schedule.effects(TARGET).items()}
        try:
            if now >= self._verify_at:
                self._forget_lost(made, windows, now)
                self._verify_at = now + self._config.resync_interval
            for key, silence_id in list(made.items()):
                window = windows.get(key)
                if window is None or window.until <= now:
                    if window is not None and window.end > now:  # ended early: the silence still runs
                        self._client.expire(silence_id)
                        self.stats.done(REMOVED)
                        log.info("expired Alertmanager silence %s of maintenance window %s", silence_id, key)
                    self._schedule.forget_effect(key, TARGET, "")
                    del made[key]
            for key, window in windows.items():
                if key not in made and window.until > now:
                    made[key] = self._client.create(silence_for(window))
                    self._schedule.keep_effect(key, TARGET, "", made[key])
                    self.stats.done(CREATED)
                    log.info(
                        "Alertmanager silence %s for maintenance window %s (%s)",
                        made[key],
                        key,
                        window.robots.text,
                    )
        except AlertmanagerError as error:
            self._failed(error, now, windows, made)
            return
        self._retry.succeeded(f"Alertmanager at {self._config.url} takes silences again")
        self._synced_revision = revision
        self.stats.synced(time.time(), 0)

    def _forget_lost(self, made: dict[str, str], windows: dict[str, Window], now: float) -> None:
        """Forget silences Alertmanager no longer has at all, so they are made again."""
        held = {silence.get("id"): silence for silence in self._client.silences()}
        for key, silence_id in list(made.items()):
            window = windows.get(key)
            if silence_id in held or window is None or window.until <= now:
                continue
            log.warning(
                "Alertmanager lost silence %s of maintenance window %s (its data?): making it again",
                silence_id,
                key,
            )
            self._schedule.forget_effect(key, TARGET, "")
            del made[key]

    def _failed(
        self, error: AlertmanagerError, now: float, windows: dict[str, Window], made: dict[str, str]
    ) -> None:
        self.stats.failed(error.reason)
        missing = sum(1 for key, window in windows.items() if key not in made and window.until > now)
        ending = sum(1 for key in made if key not in windows or windows[key].until <= now)
        self.stats.synced(time.time(), missing + ending)
        text = str(error)
        if error.status == 401:
            text = (
                f"Alertmanager at {self._config.url} refused the credentials (HTTP 401): "
                "check alertmanager.username and alertmanager.password_file"
            )
        self._retry.failed(text, now)


def silence_for(window: Window) -> dict[str, Any]:
    """The silence of `window` as POST /api/v2/silences takes it."""
    robots = window.robots
    value = re.escape(robots.text) + ".*" if robots.prefix else robots.text
    return {
        "matchers": [{"name": "robot", "value": value, "isRegex": robots.prefix, "isEqual": True}],
        "startsAt": _rfc3339(window.start),
        "endsAt": _rfc3339(window.until),
        "createdBy": window.author or "overseer",
        "comment": f"{window.comment} [Overseer maintenance window {window.key}]",
    }


def _rfc3339(at: float) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(at)) + f".{int(at % 1 * 1000):03d}Z"
