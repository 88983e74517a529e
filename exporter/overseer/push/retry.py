"""When a pusher tries a failing server again: 1 s doubling to 30 s, each new failure logged once."""

from __future__ import annotations

import logging

BACKOFF_MIN, BACKOFF_MAX = 1.0, 30.0


class Retry:
    """The next time to try a server that failed, and the failure it gave last."""

    def __init__(self, what: str, log: logging.Logger) -> None:
        """`what` names the work in log lines ("Icinga 2 push"); they go to the pusher's own `log`."""
        self._what = what
        self._log = log
        self.at = 0.0
        self.backoff = BACKOFF_MIN
        self.last_error = ""

    def due(self, now: float) -> bool:
        """Whether the server may be tried at `now`."""
        return now >= self.at

    def failed(self, text: str, now: float) -> None:
        """The server failed with `text`: warn if that is news, and wait twice as long as last time."""
        if text != self.last_error:
            self._log.warning("%s failed, retrying in %gs: %s", self._what, self.backoff, text)
        self.last_error = text
        self.at = now + self.backoff
        self.backoff = min(self.backoff * 2, BACKOFF_MAX)

    def succeeded(self, recovered: str) -> None:
        """The server answered: log `recovered` if it had failed, and wait the least next time."""
        if self.last_error:
            self._log.info("%s", recovered)
            self.last_error = ""
        self.backoff = BACKOFF_MIN

    def pause(self, until: float) -> None:
        """Try nothing before `until` (after an unexpected error)."""
        self.at = until
