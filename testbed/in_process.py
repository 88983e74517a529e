"""A whole exporter in the test process: no transport, its model fed by hand, serving on loopback."""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from overseer.app import Exporter
from overseer.config import config_from_dict
from overseer.messages import DiagnosticArray, DiagnosticStatus
from testbed.ports import free_port


@contextmanager
def in_process_exporter(
    tmp_path: Path, before_start: Callable[[Exporter], None] | None = None, **sections: Any
) -> Iterator[Exporter]:
    """An exporter with no transport, serving on loopback, its database in `tmp_path`; `sections` add.

    `before_start` may fill its model before anything (the Icinga 2 push) first looks at it.
    """
    raw: dict[str, Any] = {
        "dds": {"enabled": False},
        "web": {"listen_address": f"127.0.0.1:{free_port()}"},
        "events": {"path": str(tmp_path / "events.db")},
        "ingest": {"workers": 1},  # the tests feed the in-process model
    }
    for name, section in sections.items():
        raw[name] = {**raw.get(name, {}), **section} if isinstance(section, dict) else section
    running = Exporter(config_from_dict(raw))
    if before_start is not None:
        before_start(running)
    running.start()
    try:
        yield running
    finally:
        running.stop()


def publish(running: Exporter, robot: str, *statuses: tuple[int, str, str]) -> None:
    """Apply one array of `(level, name, message)` statuses to the exporter's model as `robot`'s."""
    array = DiagnosticArray(
        0, 0, "", tuple(DiagnosticStatus(lv, n, m, "hw", (("k", m),)) for lv, n, m in statuses)
    )
    assert running.model is not None
    running.model.apply(robot, array, "dds")
    if running.history is not None:
        running.history.store.flush()


def call(
    running: Exporter,
    path: str,
    method: str = "GET",
    body: bytes | None = None,
    headers: dict[str, str] | None = None,
) -> tuple[int, Any]:
    """The status and decoded JSON (or raw bytes) of one request to the exporter."""
    request = urllib.request.Request(
        running.server.url + path, data=body, method=method, headers=headers or {}
    )
    try:
        with urllib.request.urlopen(request, timeout=5) as response:
            answer = response.read()
            is_json = response.headers.get_content_type() == "application/json"
            return response.status, json.loads(answer) if is_json else answer
    except urllib.error.HTTPError as error:
        answer = error.read()
        return error.code, json.loads(answer) if answer.startswith(b"{") else answer
