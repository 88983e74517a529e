"""POST /-/reload: read the inventory file again, as Prometheus's lifecycle API reloads its configuration.

Off unless the exporter runs with `--web.enable-lifecycle`, as Prometheus's is; PUT works too. A file that
cannot be read answers 500 with the reason, and the inventory before it stays.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from overseer.routes import ApiRequest, JsonRoute, method_not_allowed

RELOAD_PATH = "/-/reload"


def reload_route(reload: Callable[[], str | None], enabled: bool) -> JsonRoute:
    """The route of `RELOAD_PATH`: `reload` gives None when it worked, or why it did not."""

    def answer(request: ApiRequest) -> tuple[int, dict[str, Any]]:
        if request.method not in ("POST", "PUT") or request.rest:
            return method_not_allowed(request, RELOAD_PATH, "POST")
        if not enabled:
            return 403, {
                "error": "the lifecycle API is not enabled: start the exporter with --web.enable-lifecycle"
            }
        problem = reload()
        if problem is not None:
            return 500, {"error": f"failed to reload the inventory: {problem}"}
        return 200, {"reloaded": True}

    return answer
