"""Maintenance windows as Icinga 2 downtimes for each robot's host and services, removed on an early end.

Each host this exporter made (found in Icinga at start, or made since) whose robot a window covers gets
a downtime through `POST /v1/actions/schedule-downtime` (fixed, from the window's start to its end,
`all_services`), with the window's author and comment; a service made later gets one of its own. The
hosts decide, not the robots heard since this start, so a robot switched off in its window keeps its
downtimes across a restart. The downtimes' names are kept beside the window in the exporter's
database. They are removed (`remove-downtime`) only when the window ended early or is gone, or no
longer covers the host's robot; a window that runs out lets Icinga end them itself, and a host deleted
takes its own along. The push loop calls `sync` before it delivers results, so a robot put in
maintenance is in downtime before its DOWN result arrives, and `cover` when it makes a host or service,
before that object's first result; a failure is raised to the push, which retries with its pause.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from collections.abc import Set as AbstractSet
from typing import Any

from overseer.maintenance.effects import CREATED, REMOVED, EffectStats
from overseer.maintenance.schedule import MaintenanceSchedule
from overseer.model.maintenance import Window
from overseer.push.icinga2_client import Icinga2Client, Icinga2Error, error_text
from overseer.push.icinga2_names import robot_name

log = logging.getLogger(__name__)

TARGET = "icinga2"
RESYNC_SECONDS = 10.0


class Icinga2Downtimes:
    """Keeps a downtime for every host (and its services) of a robot in a window that has not ended."""

    def __init__(self, client: Icinga2Client, schedule: MaintenanceSchedule, stats: EffectStats) -> None:
        """Schedule through `client` the downtimes `schedule`'s windows ask for."""
        self._client = client
        self._schedule = schedule
        self.stats = stats
        self._synced: tuple[int, int] | None = None
        self._resync_at = 0.0

    def due(self, created: Mapping[str, AbstractSet[str]]) -> bool:
        """True when the windows or the hosts changed since the last sync, or a while passed."""
        changed = self._synced != (self._schedule.revision, _size(created))
        return changed or self._schedule.clock() >= self._resync_at

    def sync(self, created: Mapping[str, AbstractSet[str]]) -> None:
        """Schedule the downtimes missing and remove those no longer wanted; Icinga2Error on failure.

        `created` maps each host this exporter made (found in Icinga at start, or made since) to its
        services; each host's robot is in the windows that cover it, heard since this start or not.
        """
        now = self._schedule.clock()
        revision = self._schedule.revision
        windows = {window.key: window for window in self._schedule.windows(now)}
        kept = self._schedule.effects(TARGET)
        robots = {host: robot_name(host) for host in created}
        wanted = {
            (window.key, host)
            for window in windows.values()
            if window.until > now
            for host, robot in robots.items()
            if window.robots.matches(robot)
        }
        try:
            for (key, host), reference in kept.items():
                if (key, host) in wanted:
                    continue
                window = windows.get(key)
                # Ended early, gone, or no longer covering the robot; a host deleted took them along.
                if host in created and (window is None or window.end > now):
                    for name in reference.split():
                        self._remove(name)
                    self.stats.done(REMOVED)
                    log.info("removed the Icinga 2 downtime of %s for maintenance window %s", host, key)
                self._schedule.forget_effect(key, TARGET, host)
            for key, host in sorted(wanted):
                self._complete(windows[key], host, created[host], kept.get((key, host), ""))
        except Icinga2Error:
            missing = sum(1 for item in wanted if item not in kept)
            self.stats.synced(time.time(), missing + sum(1 for item in kept if item not in wanted))
            raise
        self._synced = (revision, _size(created))
        self._resync_at = now + RESYNC_SECONDS
        self.stats.synced(time.time(), 0)

    def cover(self, host: str, services: AbstractSet[str]) -> None:
        """Schedule at once what a host or service just made lacks (before its first result); Icinga2Error.

        `host` was just made, or one of its `services`: the next `sync` would be too late for the result
        that made it.
        """
        now = self._schedule.clock()
        robot = robot_name(host)
        covering = [w for w in self._schedule.windows(now) if w.until > now and w.robots.matches(robot)]
        if not covering:
            return
        kept = self._schedule.effects(TARGET)
        for window in covering:
            self._complete(window, host, services, kept.get((window.key, host), ""))

    def _complete(self, window: Window, host: str, services: AbstractSet[str], reference: str) -> None:
        """Schedule what `host` and its `services` lack of `window` beside the downtimes in `reference`."""
        names = reference.split()
        if not names:
            names = self._schedule_downtime(window, "Host", host)
        covered = {name.rsplit("!", 1)[0] for name in names}
        for service in sorted(services):
            if f"{host}!{service}" not in covered:
                names += self._schedule_downtime(window, "Service", f"{host}!{service}")
        if names != reference.split():
            self._schedule.keep_effect(window.key, TARGET, host, " ".join(names))

    def _schedule_downtime(self, window: Window, kind: str, name: str) -> list[str]:
        """Schedule one fixed downtime of `window` for host or service `name`; the downtimes' names."""
        body: dict[str, Any] = {
            "type": kind,
            kind.lower(): name,
            "start_time": window.start,
            "end_time": window.until,
            "fixed": True,
            "author": window.author or "overseer",
            "comment": f"{window.comment} [Overseer maintenance window {window.key}]",
        }
        if kind == "Host":
            body["all_services"] = True
        status, document = self._client.request("POST", "/v1/actions/schedule-downtime", body)
        results = document.get("results") if isinstance(document, dict) else None
        if not 200 <= status < 300 or not results or not isinstance(results[0], dict):
            raise Icinga2Error(
                f"http_{status}", f"schedule-downtime {name}: HTTP {status}: {error_text(document)}", status
            )
        result = results[0]
        names = [str(result["name"])] + [str(item["name"]) for item in result.get("service_downtimes", [])]
        self.stats.done(CREATED)
        log.info("Icinga 2 downtime for %s until the end of maintenance window %s", name, window.key)
        return names

    def _remove(self, downtime: str) -> None:
        """Remove one downtime; one Icinga no longer has (removed by hand, or with its host) is fine."""
        status, document = self._client.request(
            "POST", "/v1/actions/remove-downtime", {"type": "Downtime", "downtime": downtime}
        )
        if status != 404 and not 200 <= status < 300:
            raise Icinga2Error(
                f"http_{status}", f"remove-downtime {downtime}: HTTP {status}: {error_text(document)}", status
            )


def _size(created: Mapping[str, AbstractSet[str]]) -> int:
    return len(created) + sum(len(services) for services in created.values())
