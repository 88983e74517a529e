"""Maintenance windows as Icinga 2 downtimes for each robot's host and services, removed on an early end.

A downtime is scheduled per window and robot host through `POST /v1/actions/schedule-downtime` (fixed,
from the window's start to its end, `all_services`), with the window's author and comment. A service
made later for a host in a window gets a downtime of its own. The downtimes' names are kept beside the
window in the exporter's database; a window ended early has them removed (`remove-downtime`), one
that runs out lets Icinga end them itself. The push loop calls `sync` before it delivers results, so a
robot put in maintenance is in downtime before its DOWN result arrives; a failure is raised to the
push, which retries with its pause.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from typing import Any

from overseer.maintenance.effects import CREATED, REMOVED, EffectStats
from overseer.maintenance.schedule import MaintenanceSchedule
from overseer.model.maintenance import Window
from overseer.push.icinga2_client import Icinga2Client, Icinga2Error, error_text

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

    def due(self, created: Mapping[str, set[str]]) -> bool:
        """True when the windows or the hosts changed since the last sync, or a while passed."""
        changed = self._synced != (self._schedule.revision, _size(created))
        return changed or self._schedule.clock() >= self._resync_at

    def sync(self, robot_hosts: Mapping[str, str], created: Mapping[str, set[str]]) -> None:
        """Schedule the downtimes missing and remove those of windows ended early; Icinga2Error on failure.

        `robot_hosts` maps each robot pushed to its host, `created` each host this exporter made to its
        services.
        """
        now = self._schedule.clock()
        revision = self._schedule.revision
        windows = {window.key: window for window in self._schedule.windows(now)}
        kept = self._schedule.effects(TARGET)
        wanted = {
            (window.key, host)
            for window in windows.values()
            if window.until > now
            for robot, host in robot_hosts.items()
            if window.robots.matches(robot) and host in created
        }
        try:
            for (key, host), reference in kept.items():
                if (key, host) in wanted:
                    continue
                window = windows.get(key)
                if host in created and (window is None or window.end > now):  # ended early, or forgotten
                    for name in reference.split():
                        self._remove(name)
                    self.stats.done(REMOVED)
                    log.info("removed the Icinga 2 downtime of %s for maintenance window %s", host, key)
                self._schedule.forget_effect(key, TARGET, host)
            for key, host in sorted(wanted):
                names = kept.get((key, host), "").split()
                covered = {name.rsplit("!", 1)[0] for name in names}
                if not names:
                    names = self._schedule_downtime(windows[key], "Host", host)
                    covered = {name.rsplit("!", 1)[0] for name in names}
                for service in sorted(created[host]):
                    if f"{host}!{service}" not in covered:
                        names += self._schedule_downtime(windows[key], "Service", f"{host}!{service}")
                if names != kept.get((key, host), "").split():
                    self._schedule.keep_effect(key, TARGET, host, " ".join(names))
        except Icinga2Error:
            missing = sum(1 for item in wanted if item not in kept)
            self.stats.synced(time.time(), missing + sum(1 for item in kept if item not in wanted))
            raise
        self._synced = (revision, _size(created))
        self._resync_at = now + RESYNC_SECONDS
        self.stats.synced(time.time(), 0)

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


def _size(created: Mapping[str, set[str]]) -> int:
    return len(created) + sum(len(services) for services in created.values())
