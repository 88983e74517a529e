"""GET, POST /api/v1/maintenance and DELETE /api/v1/maintenance/<id>, and maintenance in the robot documents.

Reading is open to whoever may read the endpoint; writing follows `write_access` (off unless the exporter
runs with `--web.enable-maintenance-api`), and a body must be JSON, which a plain HTML form cannot send.
"""

from __future__ import annotations

import json
from typing import Any

from overseer.maintenance.requests import parse_window_request
from overseer.maintenance.schedule import MaintenanceSchedule, WindowError
from overseer.maintenance.store import StoreUnavailable
from overseer.routes import ApiRequest
from overseer.serve.write_access import WriteAccess

MAINTENANCE_PATH = "/api/v1/maintenance"


class MaintenanceApi:
    """The maintenance routes over one schedule."""

    def __init__(self, schedule: MaintenanceSchedule, access: WriteAccess) -> None:
        """Serve `schedule`; `access` says who may write."""
        self._schedule = schedule
        self._access = access

    def answer(self, request: ApiRequest) -> tuple[int, dict[str, Any]]:
        """The status and JSON document answering `request`."""
        if request.method in ("GET", "HEAD") and not request.rest:
            return 200, self._listing(request.user)
        if request.method == "POST" and not request.rest:
            return self._write(request, self._open)
        if request.method == "DELETE" and request.rest:
            return self._write(request, self._end)
        return 405, {
            "error": f"{request.method} is not answered here; GET or POST {MAINTENANCE_PATH}, "
            f"DELETE {MAINTENANCE_PATH}/<id>"
        }

    def with_maintenance(self, document: dict[str, Any]) -> dict[str, Any]:
        """A robot's document (or GET /api/v1/robots) with each robot's `maintenance`."""
        active = self._schedule.active(self._schedule.clock())
        if "robots" in document:
            for robot in document["robots"]:
                robot["maintenance"] = self._state_document(robot["robot"], active)
        elif "robot" in document:
            document["maintenance"] = self._state_document(document["robot"], active)
        return document

    def _state_document(self, robot: str, active: list[Any]) -> dict[str, Any] | None:
        state = self._schedule.state(robot, active)
        if state is None:
            return None
        return {
            "window": state.window,
            "until": state.until,
            "comment": state.comment,
            "author": state.author,
        }

    def _listing(self, user: str | None) -> dict[str, Any]:
        now = self._schedule.clock()
        return {
            "generated_at": now,
            "can_write": self._access.may_write(user),
            "windows": [window.document(now) for window in self._schedule.windows(now)],
        }

    def _write(self, request: ApiRequest, action: Any) -> tuple[int, dict[str, Any]]:
        refused = self._access.refusal(
            request, "write maintenance windows", "the maintenance API is read-only"
        )
        if refused is not None:
            return refused
        try:
            status, document = action(request)
        except StoreUnavailable as error:
            return 503, {"error": f"{error}; nothing was changed"}
        return status, document

    def _open(self, request: ApiRequest) -> tuple[int, dict[str, Any]]:
        content_type = request.headers.get("Content-Type", "").split(";")[0].strip().lower()
        if content_type != "application/json":
            return 415, {"error": "body: send the window as application/json"}
        try:
            document = json.loads(request.body.decode("utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError):  # RecursionError: nested too deep
            return 400, {"error": "body: not a JSON document"}
        now = self._schedule.clock()
        try:
            asked = parse_window_request(document, now)
            window = self._schedule.open(
                asked.robots, asked.start, asked.end, asked.comment, request.user or ""
            )
        except WindowError as error:
            return 400, {"error": str(error)}
        return 201, {"window": window.document(max(now, window.start))}

    def _end(self, request: ApiRequest) -> tuple[int, dict[str, Any]]:
        key = request.rest
        try:
            window = self._schedule.end(key, request.user or "")
        except KeyError:
            return 404, {"error": f"no maintenance window {key[:64]!r}"}
        except WindowError as error:
            return 409, {"error": str(error)}
        return 200, {"window": window.document(self._schedule.clock())}
