"""A small client of Alertmanager's API v2: silences listed, made and expired, JSON in and out."""

from __future__ import annotations

import base64
import json
import ssl
import urllib.error
import urllib.request
from typing import Any
from urllib.parse import quote

from overseer import __version__
from overseer.config.alertmanager import AlertmanagerConfig

_MAX_ANSWER_BYTES = 32 * 1024 * 1024


class AlertmanagerError(Exception):
    """A request that did not succeed; `reason` is a short label for metrics (`http_500`, `timeout`...)."""

    def __init__(self, reason: str, text: str, status: int = 0) -> None:
        """Keep the reason label, the readable text and the HTTP status (0: no answer)."""
        super().__init__(text)
        self.reason = reason
        self.status = status


class AlertmanagerClient:
    """Calls the API v2 of the Alertmanager an `AlertmanagerConfig` names."""

    def __init__(self, config: AlertmanagerConfig) -> None:
        """Prepare TLS and credentials; nothing is sent yet."""
        self._config = config
        self._context = ssl.create_default_context(cafile=config.ca_file or None)
        self._headers = {
            "Accept": "application/json",
            "Content-Type": "application/json",
            "User-Agent": f"overseer/{__version__}",
        }
        if config.password:
            token = base64.b64encode(f"{config.username}:{config.password}".encode()).decode()
            self._headers["Authorization"] = f"Basic {token}"

    def silences(self) -> list[dict[str, Any]]:
        """Every silence Alertmanager holds (active, pending and recently expired)."""
        answer = self._request("GET", "/api/v2/silences")
        if not isinstance(answer, list):
            raise AlertmanagerError("bad_answer", "GET /api/v2/silences: the answer is not a list")
        return [silence for silence in answer if isinstance(silence, dict)]

    def create(self, silence: dict[str, Any]) -> str:
        """Make `silence`; its id."""
        answer = self._request("POST", "/api/v2/silences", silence)
        silence_id = answer.get("silenceID") if isinstance(answer, dict) else None
        if not isinstance(silence_id, str) or not silence_id:
            raise AlertmanagerError("bad_answer", "POST /api/v2/silences: no silenceID in the answer")
        return silence_id

    def expire(self, silence_id: str) -> None:
        """Expire silence `silence_id` now; one that is gone or over already is fine."""
        try:
            self._request("DELETE", f"/api/v2/silence/{quote(silence_id, safe='')}")
        except AlertmanagerError as error:
            if error.status == 404 or "already expired" in str(error):
                return
            raise

    def _request(self, method: str, path: str, body: dict[str, Any] | None = None) -> Any:
        """Send one request; the parsed JSON of a 2xx answer, AlertmanagerError otherwise."""
        url = self._config.url + path
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(url, data=data, method=method, headers=self._headers)
        try:
            with urllib.request.urlopen(
                request, timeout=self._config.timeout, context=self._context
            ) as response:
                payload = response.read(_MAX_ANSWER_BYTES)
        except urllib.error.HTTPError as error:
            text = " ".join(error.read(2000).decode("utf-8", "replace").split())[:300]
            raise AlertmanagerError(
                f"http_{error.code}", f"{method} {url}: HTTP {error.code}: {text}", error.code
            ) from None
        except TimeoutError:
            raise AlertmanagerError(
                "timeout", f"no answer from {self._config.url} within {self._config.timeout:g}s"
            ) from None
        except (urllib.error.URLError, OSError) as error:
            reason = getattr(error, "reason", error)
            label = "tls" if isinstance(reason, ssl.SSLError) else "connection"
            if isinstance(reason, TimeoutError):
                label = "timeout"
            text = f"cannot reach {self._config.url}: {reason}"
            del reason  # the error or its cause, whose traceback holds this frame: a cycle (Icinga2Client)
            raise AlertmanagerError(label, text) from None
        try:
            return json.loads(payload) if payload else None
        except (ValueError, RecursionError):
            raise AlertmanagerError("bad_answer", f"{method} {url}: the answer is not JSON") from None
