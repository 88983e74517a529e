"""GET /api/v1/events as a JSON route the HTTP endpoint serves: the query read, the store asked."""

from __future__ import annotations

from typing import Any

from overseer.history.query import QueryError, parse_event_query
from overseer.history.store import EventStore, EventsUnavailable
from overseer.routes import ApiRequest, JsonRoute, method_not_allowed

EVENTS_PATH = "/api/v1/events"


def events_route(store: EventStore | None) -> JsonRoute:
    """The route of `store`'s events; with no store (the history disabled), a 404 saying so."""

    def answer(request: ApiRequest) -> tuple[int, dict[str, Any]]:
        if request.method not in ("GET", "HEAD"):
            return method_not_allowed(request, EVENTS_PATH, "GET")
        if store is None:
            return 404, {"error": "the event history is disabled (events.enabled: false)"}
        try:
            events, cursor = store.query(parse_event_query(request.query))
        except QueryError as error:
            return 400, {"error": str(error)}
        except EventsUnavailable as error:
            return 503, {"error": f"the event history is unavailable: {error}"}
        return 200, {"events": events, "next": cursor}

    return answer
