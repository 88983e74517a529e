"""POST /api/v1/retirements: forget a robot that is down and not listed, behind the maintenance API's guard.

The body is JSON, `{"robot": "site_a/robot7", "comment": "sold"}`; the answer says what happened: 200
retired (the event history records it with the user), 404 an unknown robot, 409 one listed in the
inventory or still up.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

from overseer.inventory.retirement import LISTED, RETIRED, UP, Retirement
from overseer.routes import ApiRequest, method_not_allowed
from overseer.serve.write_access import WriteAccess

RETIREMENTS_PATH = "/api/v1/retirements"
MAX_COMMENT = 1024
_STATUS = {RETIRED: 200, LISTED: 409, UP: 409}

Retire = Callable[[str, str, str], Retirement]  # robot, author, comment


class RetireApi:
    """The retirements route over one way to retire robots."""

    def __init__(self, retire: Retire, access: WriteAccess) -> None:
        """Retire through `retire`; `access` says who may."""
        self._retire = retire
        self._access = access

    def answer(self, request: ApiRequest) -> tuple[int, dict[str, Any]]:
        """The status and JSON document answering `request`."""
        if request.method != "POST" or request.rest:
            return method_not_allowed(request, RETIREMENTS_PATH, "POST")
        refused = self._access.refusal(request, "retire robots", "retiring robots is off")
        if refused is not None:
            return refused
        content_type = request.headers.get("Content-Type", "").split(";")[0].strip().lower()
        if content_type != "application/json":
            return 415, {"error": 'body: send {"robot": NAME, "comment": TEXT} as application/json'}
        try:
            document = json.loads(request.body.decode("utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError):
            return 400, {"error": "body: not a JSON document"}
        robot = document.get("robot") if isinstance(document, dict) else None
        comment = document.get("comment", "") if isinstance(document, dict) else None
        if not isinstance(robot, str) or not robot:
            return 400, {"error": "robot: expected the name of a robot"}
        if not isinstance(comment, str) or len(comment) > MAX_COMMENT:
            return 400, {"error": f"comment: expected text of at most {MAX_COMMENT} characters"}
        retirement = self._retire(robot, request.user or "", comment)
        status = _STATUS.get(retirement.outcome, 404)
        if status != 200:
            return status, {"error": retirement.text, "outcome": retirement.outcome}
        return 200, {"robot": robot, "outcome": retirement.outcome, "message": retirement.text}
