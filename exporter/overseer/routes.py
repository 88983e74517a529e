"""The one route type of the exporter's JSON API: the request as a route needs it, and its answer.

The HTTP endpoint (`serve/`) answers the fleet's paths itself and hands other outputs' paths (the event
history's, the maintenance windows') to the routes they give it, all of this one type.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

MAX_BODY_BYTES = 16_384  # a request body beyond this is refused (413) before it is read


@dataclass(frozen=True)
class ApiRequest:
    """What a JSON route needs of a request: method, the path past the route's, query, body, who asks."""

    method: str
    rest: str  # the path after the route's own, without its leading "/" ('' for the route itself)
    query: str
    body: bytes
    user: str | None  # the basic-auth user the request proved to be
    headers: Mapping[str, str]


# A JSON path the endpoint serves for another output: its status and document for a request.
JsonRoute = Callable[[ApiRequest], tuple[int, dict[str, Any]]]


def method_not_allowed(request: ApiRequest, path: str, allowed: str) -> tuple[int, dict[str, Any]]:
    """The 405 answer to a method a route does not answer."""
    return 405, {"error": f"{request.method} is not answered at {path}; {allowed} it"}
