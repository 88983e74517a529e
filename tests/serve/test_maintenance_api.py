"""/api/v1/maintenance on a real exporter in this process: who may write, hostile input, what it changes.

Each test runs its own exporter with basic auth (a writer and a reader) on loopback; windows are kept in
the exporter's SQLite file in the test's directory.
"""

from __future__ import annotations

import json
import time
from base64 import b64encode
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import bcrypt
import pytest

from overseer.app import Exporter
from testbed.in_process import call, in_process_exporter, publish

HASH = bcrypt.hashpw(b"secret", bcrypt.gensalt(rounds=4)).decode()
WRITER = {"Authorization": "Basic " + b64encode(b"alice:secret").decode()}
READER = {"Authorization": "Basic " + b64encode(b"bob:secret").decode()}
JSON = {"Content-Type": "application/json"}


@contextmanager
def exporter(tmp_path: Path, writable: bool = True, **sections: Any) -> Iterator[Exporter]:
    """An exporter whose basic auth knows alice (a writer) and bob (a reader)."""
    web_config = tmp_path / "web.yml"
    web_config.write_text(f"basic_auth_users:\n  alice: '{HASH}'\n  bob: '{HASH}'\n", encoding="utf-8")
    sections = {
        "web": {"config_file": str(web_config), "enable_maintenance_api": writable},
        "maintenance": {"writers": ["alice"]},
        **sections,
    }
    with in_process_exporter(tmp_path, **sections) as running:
        yield running


def open_window(running: Exporter, body: object, headers: dict[str, str] | None = None) -> tuple[int, Any]:
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    return call(running, "/api/v1/maintenance", "POST", data, {**WRITER, **JSON, **(headers or {})})


def metric_line(running: Exporter, prefix: str) -> list[str]:
    _, body = call(running, "/metrics", headers=WRITER)
    text = body.decode() if isinstance(body, bytes) else ""
    return [line for line in text.splitlines() if line.startswith(prefix)]


def test_a_writer_opens_a_window_and_every_view_says_so(tmp_path: Path) -> None:
    with exporter(tmp_path) as running:
        publish(running, "site_a/robot7", (2, "/Laser", "no scans"))
        publish(running, "robot1", (0, "/Power", "ok"))
        status, answer = open_window(
            running, {"robots": "site_a/", "duration": "2h", "comment": "battery swap"}
        )
        assert status == 201, answer
        window = answer["window"]
        assert (window["robots"], window["prefix"], window["author"], window["active"]) == (
            "site_a/",
            True,
            "alice",
            True,
        )
        assert window["end"] - window["start"] == pytest.approx(7200, abs=2)
        _, listing = call(running, "/api/v1/maintenance", headers=WRITER)
        _, robots = call(running, "/api/v1/robots", headers=WRITER)
        _, robot = call(running, "/api/v1/robots/site_a%2Frobot7", headers=WRITER)
        in_maintenance = metric_line(running, "ros_diagnostics_robot_maintenance{")
        ends = metric_line(running, "ros_diagnostics_robot_maintenance_end_timestamp_seconds{")
    assert listing["can_write"] is True and [w["id"] for w in listing["windows"]] == [window["id"]]
    by_name = {entry["robot"]: entry["maintenance"] for entry in robots["robots"]}
    assert by_name["robot1"] is None
    assert by_name["site_a/robot7"]["comment"] == "battery swap"
    assert robot["maintenance"] == {
        "window": window["id"],
        "until": window["end"],
        "comment": "battery swap",
        "author": "alice",
    }
    assert in_maintenance == [
        'ros_diagnostics_robot_maintenance{robot="robot1"} 0.0',
        'ros_diagnostics_robot_maintenance{robot="site_a/robot7"} 1.0',
    ]
    assert len(ends) == 1 and ends[0].startswith(
        'ros_diagnostics_robot_maintenance_end_timestamp_seconds{robot="site_a/'
    )


def test_ending_a_window_early_frees_the_robot_and_the_history_records_both(tmp_path: Path) -> None:
    with exporter(tmp_path) as running:
        publish(running, "robot3", (1, "/Motor", "warm"))
        _, answer = open_window(running, {"robots": "robot3", "end": time.time() + 600, "comment": "wheel"})
        key = answer["window"]["id"]
        status, ended = call(running, f"/api/v1/maintenance/{key}", "DELETE", headers=WRITER)
        assert status == 200 and ended["window"]["active"] is False and ended["window"]["ended_early"] is True
        _, robot = call(running, "/api/v1/robots/robot3", headers=WRITER)
        again, refused = call(running, f"/api/v1/maintenance/{key}", "DELETE", headers=WRITER)
        missing, _ = call(running, "/api/v1/maintenance/w999", "DELETE", headers=WRITER)
        assert running.history is not None
        running.history.store.flush()
        _, events = call(running, "/api/v1/events?robot=robot3", headers=WRITER)
    assert robot["maintenance"] is None
    assert (again, missing) == (409, 404) and "is over already" in refused["error"]
    kinds = [(event["kind"], event["message"]) for event in events["events"]]
    assert ("maintenance_start", "wheel") in kinds and ("maintenance_end", "wheel") in kinds
    start = next(event for event in events["events"] if event["kind"] == "maintenance_start")
    assert {"key": "author", "value": "alice"} in start["values"]


def test_windows_survive_a_restart(tmp_path: Path) -> None:
    with exporter(tmp_path) as running:
        _, answer = open_window(running, {"robots": "robot9", "duration": "1h", "comment": "parked"})
    with exporter(tmp_path) as restarted:
        _, listing = call(restarted, "/api/v1/maintenance", headers=READER)
    assert [window["id"] for window in listing["windows"]] == [answer["window"]["id"]]
    assert listing["can_write"] is False  # bob reads only


@pytest.mark.parametrize(
    ("writable", "headers", "status", "message"),
    [
        (
            False,
            {},
            403,
            "the maintenance API is read-only: start the exporter with --web.enable-maintenance-api",
        ),
        (True, READER, 403, "user 'bob' may not write maintenance windows (maintenance.writers)"),
        (
            True,
            {"Origin": "https://evil.example"},
            403,
            "cross-site request refused (Origin 'https://evil.example'",
        ),
        (
            True,
            {"Sec-Fetch-Site": "cross-site"},
            403,
            "cross-site request refused (Sec-Fetch-Site: cross-site)",
        ),
        (True, {"Origin": "null"}, 403, "cross-site request refused"),
        (
            True,
            {"Content-Type": "application/x-www-form-urlencoded"},
            415,
            "body: send the window as application/json",
        ),
    ],
)
def test_who_may_write_and_from_where(
    tmp_path: Path, writable: bool, headers: dict[str, str], status: int, message: str
) -> None:
    with exporter(tmp_path, writable) as running:
        answer = open_window(running, {"robots": "r1", "duration": "1h", "comment": "x"}, headers)
        _, listing = call(running, "/api/v1/maintenance", headers=WRITER)
    assert answer[0] == status and message in answer[1]["error"]
    assert listing["windows"] == []  # nothing was written


def test_the_page_of_the_exporter_itself_may_write(tmp_path: Path) -> None:
    with exporter(tmp_path) as running:
        host = running.server.url.removeprefix("http://")
        same = {"Origin": running.server.url, "Host": host, "Sec-Fetch-Site": "same-origin"}
        status, _ = open_window(running, {"robots": "r1", "duration": "1h", "comment": "from the page"}, same)
    assert status == 201


def test_writing_without_any_user_configured_is_refused(tmp_path: Path) -> None:
    with in_process_exporter(tmp_path, web={"enable_maintenance_api": True}) as running:
        status, answer = call(
            running, "/api/v1/maintenance", "POST", b'{"robots":"r1","duration":"1h","comment":"x"}', JSON
        )
    assert status == 403 and "writing needs a user" in answer["error"]


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (b"not json", "body: not a JSON document"),
        (b"[1, 2]", "body: expected a JSON object"),
        (b"\xff\xfe{}", "body: not a JSON document"),
        ({"robots": "r 1", "duration": "1h", "comment": "x"}, "robots: expected a robot name"),
        ({"robots": "../../etc", "duration": "1h", "comment": "x"}, "robots: expected a robot name"),
        ({"robots": ["r1"], "duration": "1h", "comment": "x"}, "robots: expected a robot name"),
        ({"robots": "r1", "comment": "x"}, "end: give either end or duration"),
        ({"robots": "r1", "end": 1, "duration": "1h", "comment": "x"}, "end: give either end or duration"),
        ({"robots": "r1", "duration": "soon", "comment": "x"}, "duration: expected a duration such as 5s"),
        ({"robots": "r1", "duration": "40d", "comment": "x"}, "end: a window lasts at most 31 days"),
        (
            {"robots": "r1", "end": "tomorrow", "comment": "x"},
            "end: expected unix seconds or an RFC 3339 time",
        ),
        ({"robots": "r1", "end": "2026-11-24T06:00:00", "comment": "x"}, "end: expected unix seconds"),
        ({"robots": "r1", "end": 1e308, "comment": "x"}, "end: a window lasts at most 31 days"),
        ({"robots": "r1", "start": 1.0, "duration": "1h", "comment": "x"}, "start: must not be in the past"),
        ({"robots": "r1", "duration": "1h", "comment": 7}, "comment: expected a string saying why, got 7"),
        ({"robots": "r1", "duration": "1h", "comment": "a\nb"}, "comment: expected 1 to 1000 characters"),
        ({"robots": "r1", "duration": "1h", "comment": "\u0000"}, "comment: expected 1 to 1000 characters"),
        ({"robots": "r1", "duration": "1h", "comment": "x" * 1001}, "comment: expected 1 to 1000 characters"),
        ({"robots": "r1", "duration": "1h", "comment": "x", "author": "mallory"}, "'author': unknown field"),
        (b'{"robots": "r1", "start": NaN, "duration": "1h", "comment": "x"}', "start: expected unix seconds"),
        (b'{"robots": "r1", "end": Infinity, "comment": "x"}', "end: expected unix seconds"),
        (b"[" * 8000 + b"]" * 8000, "body: not a JSON document"),
        ({"robots": "/", "duration": "1h", "comment": "x"}, "robots: expected a robot name"),
        ({"robots": "r\u00f6bot", "duration": "1h", "comment": "x"}, "robots: expected a robot name"),
        ({"robots": "r1" * 200, "duration": "1h", "comment": "x"}, "robots: expected a robot name"),
        ({"robots": "r1", "duration": "-1h", "comment": "x"}, "duration: expected a duration"),
        ({"robots": "r1", "duration": 0, "comment": "x"}, "duration: must be a positive duration"),
        ({"robots": "r1", "start": True, "duration": "1h", "comment": "x"}, "start: expected unix seconds"),
        (
            {"robots": "r1", "end": "9999-12-31T23:59:59Z", "comment": "x"},
            "end: a window lasts at most 31 days",
        ),
        (
            {"robots": "r1", "start": "2999-01-01T00:00:00+00:00", "duration": "1h", "comment": "x"},
            "start: must be",
        ),
        ({"robots": "r1", "duration": "1h", "comment": "   "}, "comment: expected 1 to 1000 characters"),
        ({"robots": "r1", "duration": "1h", "comment": "a\u2028b"}, "comment: expected 1 to 1000 characters"),
        (
            {"robots": "r1", "duration": "1h", "comment": "x\u0085y"},
            "comment: expected 1 to 1000 characters",
        ),
    ],
)
def test_every_bad_field_is_a_400_naming_it(tmp_path: Path, body: object, message: str) -> None:
    with exporter(tmp_path) as running:
        status, answer = open_window(running, body)
        _, listing = call(running, "/api/v1/maintenance", headers=WRITER)
    assert status == 400 and message in answer["error"], answer
    assert listing["windows"] == []


def test_a_body_beyond_the_limit_is_refused_unread(tmp_path: Path) -> None:
    with exporter(tmp_path) as running:
        status, answer = open_window(running, b"{" + b" " * 20_000 + b"}")
        healthy, _ = call(running, "/api/v1/maintenance", headers=WRITER)
    assert status == 413 and "at most 16384 bytes" in answer["error"]
    assert healthy == 200


def test_a_hostile_comment_is_kept_as_text_and_served_as_json(tmp_path: Path) -> None:
    comment = '</script><img src=x onerror=alert(1)> "quoted" \\ ☃ 🤖'
    with exporter(tmp_path) as running:
        status, _ = open_window(running, {"robots": "r1", "duration": "1h", "comment": comment})
        _, listing = call(running, "/api/v1/maintenance", headers=WRITER)
    assert status == 201 and listing["windows"][0]["comment"] == comment


def test_a_recurring_window_of_the_configuration_cannot_be_ended_through_the_api(tmp_path: Path) -> None:
    windows = {"writers": ["alice"], "windows": [{"robots": "night/", "from": "00:00", "to": "23:59"}]}
    with exporter(tmp_path, maintenance=windows) as running:
        _, listing = call(running, "/api/v1/maintenance", headers=WRITER)
        key = listing["windows"][0]["id"] if listing["windows"][0]["active"] else listing["windows"][-1]["id"]
        status, answer = call(running, f"/api/v1/maintenance/{key}", "DELETE", headers=WRITER)
    assert listing["windows"][0]["recurring"] is True
    assert status == 409 and "recurs as the configuration says" in answer["error"]


@pytest.mark.parametrize(
    "key",
    ["w99", "w0", "x1", "w1%00", "..%2F..%2Fmetrics", "w" + "9" * 5000, "r0@1", "%FF%FE", "w1%20OR%201=1"],
)
def test_ending_a_window_that_does_not_exist_is_a_404_and_changes_nothing(tmp_path: Path, key: str) -> None:
    with exporter(tmp_path) as running:
        status, _ = open_window(running, {"robots": "r1", "duration": "1h", "comment": "kept"})
        assert status == 201
        ended, answer = call(running, f"/api/v1/maintenance/{key}", "DELETE", None, WRITER)
        _, listing = call(running, "/api/v1/maintenance", headers=WRITER)
    assert ended == 404 and answer["error"].startswith("no maintenance window"), answer
    assert [(w["id"], w["active"]) for w in listing["windows"]] == [("w1", True)]
