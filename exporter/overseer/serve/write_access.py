"""Who may write through the JSON API: nobody unless the exporter was started to allow it, then named users.

As Prometheus keeps its admin API off, writing is off unless its flag turns it on; then it needs a user
the web config's basic auth proved and `maintenance.writers` lists. A browser's cross-site request is
refused (its `Origin` or `Sec-Fetch-Site` says so).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any
from urllib.parse import urlsplit

from overseer.routes import ApiRequest

_SAME_SITE = ("same-origin", "none")


class WriteAccess:
    """The one rule for every write of the API (maintenance windows, retirements)."""

    def __init__(self, writers: tuple[str, ...], writable: bool) -> None:
        """`writers` may write when `writable` (`--web.enable-maintenance-api`)."""
        self.writers = frozenset(writers)
        self.writable = writable

    def may_write(self, user: str | None) -> bool:
        """True when `user` may write."""
        return self.writable and user in self.writers

    def refusal(self, request: ApiRequest, what: str, closed: str) -> tuple[int, dict[str, Any]] | None:
        """The 403 answer to `request`, which would `what`, or None when it may; `closed` says it is off."""
        if not self.writable:
            return 403, {"error": f"{closed}: start the exporter with --web.enable-maintenance-api to write"}
        if request.user is None:
            return 403, {
                "error": "writing needs a user: give basic_auth_users in --web.config.file and name "
                "the user in maintenance.writers"
            }
        if request.user not in self.writers:
            return 403, {"error": f"user {request.user!r} may not {what} (maintenance.writers)"}
        refused = _cross_site(request.headers)
        return None if refused is None else (403, {"error": refused})


def _cross_site(headers: Mapping[str, str]) -> str | None:
    """Why a browser's request from another site is refused, or None when it is not one."""
    fetch_site = headers.get("Sec-Fetch-Site")
    if fetch_site is not None and fetch_site.lower() not in _SAME_SITE:
        return f"cross-site request refused (Sec-Fetch-Site: {fetch_site[:32]})"
    origin = headers.get("Origin")
    if origin is not None:
        host = headers.get("Host", "")
        if origin == "null" or urlsplit(origin).netloc.lower() != host.lower():
            return (
                f"cross-site request refused (Origin {origin[:100]!r} is not this exporter, {host[:100]!r})"
            )
    return None
