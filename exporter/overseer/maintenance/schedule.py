"""The one owner of the exporter's maintenance windows: it opens and ends them, and knows who is in one.

One-off windows come from the API and the command line and are kept in the store; recurring ones come
from the configuration. Every robot's state is judged here only; the outputs (metrics, API and status
page, the check, Alertmanager silences, Icinga 2 downtimes, the event history) ask. A window's start
and end are events of the history, with its author and comment, told by a check every second.
"""

from __future__ import annotations

import logging
import math
import threading
import time
import unicodedata
from collections.abc import Callable
from dataclasses import dataclass

from overseer.clock import steady_time
from overseer.config.maintenance import MaintenanceConfig
from overseer.maintenance.store import StoreUnavailable, WindowStore
from overseer.model.events import Event, EventKind, EventSink
from overseer.model.maintenance import RobotSelector, Window

log = logging.getLogger(__name__)

MAX_LENGTH_SECONDS = 31 * 86400.0  # a longer absence is a decommissioning, not a maintenance
MAX_AHEAD_SECONDS = 366 * 86400.0
MAX_COMMENT_LENGTH = 1000
PAST_TOLERANCE_SECONDS = 300.0  # a start this far back is taken as now (clocks differ)
CHECK_INTERVAL_SECONDS = 1.0


class WindowError(ValueError):
    """A window that cannot be opened or ended; the message names the field and what is wrong."""


@dataclass(frozen=True)
class RobotMaintenance:
    """A robot in maintenance: the window that lasts longest of those covering it now."""

    window: str
    until: float
    comment: str
    author: str


class MaintenanceSchedule:
    """One-off and recurring windows; thread-safe. `store` None keeps them in memory only."""

    def __init__(
        self,
        config: MaintenanceConfig,
        store: WindowStore | None,
        events: EventSink | None = None,
        clock: Callable[[], float] = steady_time,
    ) -> None:
        """Windows of `config` and `store`; `events` receives each window's start and end.

        `clock` judges when windows start and end: by default a wall clock that a step of the system's
        does not move (`overseer.clock`).
        """
        self.config = config
        self.store = store
        self._events = events
        self.clock = clock
        self._lock = threading.Lock()
        self._memory: list[Window] = []  # one-off windows when there is no store
        self._memory_effects: dict[tuple[str, str, str], str] = {}  # and their effects
        self._next_memory_id = 1
        self._started: set[str] = set()
        self._ended: set[str] = set()
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self.revision = 0  # grows with every change of the windows; outputs compare it to act at once
        now = clock()
        self._started = {window.key for window in self.windows(now) if window.start <= now}
        self._ended = {window.key for window in self.windows(now) if window.until <= now}

    def start(self) -> None:
        """Tell windows starting and ending, every `CHECK_INTERVAL_SECONDS` from now on."""
        self._thread = threading.Thread(target=self._check_loop, name="maintenance", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop telling."""
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout=5)

    def close(self) -> None:
        """Close the windows' database: the last thing the exporter does, once nothing else asks."""
        if self.store is not None:
            self.store.close()

    def windows(self, now: float) -> list[Window]:
        """Every window ending after a day ago: one-off ones, and the recurring ones' occurrences near now."""
        with self._lock:
            return sorted(self._windows(now), key=lambda window: (window.start, window.key))

    def active(self, now: float) -> list[Window]:
        """The windows that hold now."""
        return [window for window in self.windows(now) if window.active(now)]

    def state(self, robot: str, active: list[Window]) -> RobotMaintenance | None:
        """`robot`'s maintenance among the `active` windows, or None when it is in none."""
        covering = [window for window in active if window.robots.matches(robot)]
        if not covering:
            return None
        longest = max(covering, key=lambda window: (window.until, window.key))
        return RobotMaintenance(longest.key, longest.until, longest.comment, longest.author)

    def open(
        self, robots: RobotSelector, start: float | None, end: float, comment: str, author: str
    ) -> Window:
        """A new one-off window for `robots` from `start` (None: now) to `end`; `WindowError` if invalid."""
        now = self.clock()
        begins = now if start is None or now - PAST_TOLERANCE_SECONDS <= start <= now else start
        if not math.isfinite(begins) or begins < now - PAST_TOLERANCE_SECONDS:
            raise WindowError("start: must not be in the past")
        if begins > now + MAX_AHEAD_SECONDS:
            raise WindowError("start: must be within a year from now")
        if not math.isfinite(end) or end <= begins:
            raise WindowError("end: must be after the start")
        if end - begins > MAX_LENGTH_SECONDS:
            raise WindowError("end: a window lasts at most 31 days")
        text = comment.strip()
        if not text or len(text) > MAX_COMMENT_LENGTH or any(_breaks_a_line(char) for char in text):
            raise WindowError(
                f"comment: expected 1 to {MAX_COMMENT_LENGTH} characters with no control characters"
            )
        with self._lock:
            if self.store is not None:
                window = self.store.add(robots, begins, end, text, author, now)
            else:
                window = Window(f"w{self._next_memory_id}", robots, begins, end, text, author)
                self._next_memory_id += 1
                self._memory.append(window)
            self.revision += 1
        log.info(
            "maintenance window %s opened by %s for %s until %s: %s",
            window.key,
            author,
            robots.text,
            _iso(end),
            text,
        )
        self.check(now)
        return window

    def end(self, key: str, author: str) -> Window:
        """End one-off window `key` now; `KeyError` for no such window, `WindowError` when it cannot end."""
        now = self.clock()
        window = next((window for window in self.windows(now) if window.key == key), None)
        if window is None:
            raise KeyError(key)
        if window.recurring:
            raise WindowError(f"{key} recurs as the configuration says (maintenance.windows): end it there")
        if window.until <= now:
            raise WindowError(f"{key} is over already")
        with self._lock:
            if self.store is not None:
                self.store.end_early(key, now)
            else:
                self._memory = [
                    Window(w.key, w.robots, w.start, w.end, w.comment, w.author, ended_early=now)
                    if w.key == key
                    else w
                    for w in self._memory
                ]
            self.revision += 1
        log.info("maintenance window %s of %s ended early by %s", key, window.robots.text, author)
        self.check(now)
        return next(window for window in self.windows(now) if window.key == key)

    def check(self, now: float | None = None) -> None:
        """Tell the windows that started or ended since the last check."""
        now = self.clock() if now is None else now
        events = []
        with self._lock:
            for window in self._windows(now):
                if window.start <= now and window.key not in self._started:
                    self._started.add(window.key)
                    events.append(_event(window, "maintenance_start", window.start))
                if window.until <= now and window.key not in self._ended:
                    self._ended.add(window.key)
                    events.append(_event(window, "maintenance_end", window.until))
            if events:
                self.revision += 1
        if events and self._events is not None:
            self._events(events)

    def effects(self, target: str) -> dict[tuple[str, str], str]:
        """(window key, subject) → reference of what `target` (alertmanager, icinga2) made of each window."""
        if self.store is not None:
            return self.store.effects(target)
        with self._lock:
            return {(w, s): ref for (w, t, s), ref in self._memory_effects.items() if t == target}

    def keep_effect(self, window: str, target: str, subject: str, reference: str) -> None:
        """Remember what `target` made of `window` for `subject`: `reference` (silence id, downtime names)."""
        if self.store is not None:
            self.store.keep_effect(window, target, subject, reference)
        else:
            with self._lock:
                self._memory_effects[window, target, subject] = reference

    def forget_effect(self, window: str, target: str, subject: str) -> None:
        """The effect is gone (removed, or over by itself)."""
        if self.store is not None:
            self.store.forget_effect(window, target, subject)
        else:
            with self._lock:
                self._memory_effects.pop((window, target, subject), None)

    def _windows(self, now: float) -> list[Window]:
        """`windows` unsorted, for callers holding the lock."""
        since = now - 86400.0
        one_off = self.store.windows(since) if self.store is not None else list(self._memory)
        recurring = [o for w in self.config.windows for o in w.occurrences(now) if o.until > since]
        return [*one_off, *recurring]

    def _check_loop(self) -> None:
        while not self._stopping.wait(CHECK_INTERVAL_SECONDS):
            try:
                self.check()
            except Exception:  # a bug here must not end the windows' events for good
                log.exception("maintenance check failed")


def _breaks_a_line(char: str) -> bool:
    """Control characters (C0, DEL, C1) and Unicode's line and paragraph separators: a comment is one line."""
    return unicodedata.category(char) in ("Cc", "Zl", "Zp")


def open_schedule(config: MaintenanceConfig, path: str, events: EventSink | None) -> MaintenanceSchedule:
    """The exporter's schedule, its windows kept in the SQLite file at `path` (in memory if it cannot be)."""
    try:
        store: WindowStore | None = WindowStore(path)
    except StoreUnavailable as error:
        log.error("%s; maintenance windows opened now are kept in memory only, until a restart", error)
        store = None
    return MaintenanceSchedule(config, store, events)


def _event(window: Window, kind: EventKind, at: float) -> Event:
    values = (("window", window.key), ("author", window.author), ("until", _iso(window.until)))
    return Event(at, window.robots.text, kind, message=window.comment, values=values)


def _iso(at: float) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(at))
