"""GET /api/v1/events on the real exporter, in this process and fed through its model: shape, filters."""

from __future__ import annotations

import re
import urllib.error
import urllib.request
from base64 import b64encode
from pathlib import Path
from typing import Any
from urllib.parse import quote, urlencode

import bcrypt
import pytest

from overseer.app import Exporter
from overseer.serve.exposition_formats import OPENMETRICS, TEXT
from overseer.serve.render_ahead import RenderAheadCollector
from overseer.serve.render_timing import RenderTimingCollector
from overseer.sources import enabled_transports
from support.maintenance_oracle import MaintenanceOracle
from support.oracle import OracleCollector, oracle_openmetrics, oracle_registry, oracle_text
from testbed.in_process import call, in_process_exporter, publish

HOSTILE = ['quote"d', "back\\slash", "new\nline", "unicode ☃ 🤖", "</script><b>", "tab\there", "\u2028sep"]


exporter = in_process_exporter


def get(running: Exporter, path: str, headers: dict[str, str] | None = None) -> tuple[int, Any]:
    return call(running, path, headers=headers)


def test_events_answer_in_the_contracts_shape_newest_first(tmp_path: Path) -> None:
    with exporter(tmp_path) as running:
        publish(running, "robot1", (0, "/Power/Battery", "ok"))
        publish(running, "robot1", (2, "/Power/Battery", "voltage low"))
        status, document = get(running, "/api/v1/events")
    assert status == 200 and set(document) == {"events", "next"} and document["next"] is None
    newest, oldest = document["events"]
    assert set(newest) == {
        "id",
        "time",
        "robot",
        "component",
        "hardware_id",
        "kind",
        "old_level",
        "new_level",
        "old_state",
        "new_state",
        "message",
        "values",
    }
    assert (newest["kind"], newest["old_state"], newest["new_state"], newest["message"]) == (
        "level",
        "OK",
        "ERROR",
        "voltage low",
    )
    assert newest["values"] == [{"key": "k", "value": "voltage low"}] and newest["hardware_id"] == "hw"
    assert oldest["kind"] == "appeared" and oldest["old_level"] is None and newest["id"] > oldest["id"]


def test_hostile_names_and_messages_come_back_intact_and_json_escaped(tmp_path: Path) -> None:
    with exporter(tmp_path) as running:
        for text in HOSTILE:
            publish(running, f"robot/{text}", (1, text, text))
        status, document = get(running, "/api/v1/events?limit=1000")
        exact = get(running, "/api/v1/events?" + urlencode({"robot": "robot/" + HOSTILE[0]}))[1]
        with urllib.request.urlopen(running.server.url + "/api/v1/events", timeout=5) as response:
            raw = response.read()
    assert status == 200
    returned = sorted((e["robot"], e["component"], e["message"]) for e in document["events"])
    assert returned == sorted((f"robot/{t}", t, t) for t in HOSTILE)
    assert [e["component"] for e in exact["events"]] == [HOSTILE[0]]
    assert b"\n" not in raw.strip() and b"\\n" in raw and b"\\\\" in raw  # escaped, never raw


def test_filters_and_paging_over_http(tmp_path: Path) -> None:
    with exporter(tmp_path) as running:
        for i in range(25):
            publish(running, "robot1", (i % 3, "/Motor/Motor1", f"step {i}"))
        publish(running, "robot10", (2, "/Laser/Laser1", "no scans"))
        _, errors = get(running, "/api/v1/events?level=ERROR&robot=robot1")
        _, warn_or_error = get(running, "/api/v1/events?level=error,WARN")
        _, laser = get(running, "/api/v1/events?component=Laser")
        pages, path = [], "/api/v1/events?robot=robot1&limit=7"
        while True:
            _, page = get(running, path)
            pages.append(page["events"])
            if page["next"] is None:
                break
            path = "/api/v1/events?" + urlencode({"robot": "robot1", "limit": 7, "before": page["next"]})
        since = get(running, "/api/v1/events?since=2000-01-01T00:00:00Z&until=2999-01-01T00:00:00%2B02:00")[1]
        nothing = get(running, "/api/v1/events?until=2000-01-01T00:00:00Z")[1]
    assert {e["new_state"] for e in errors["events"]} == {"ERROR"} and len(errors["events"]) == 8
    assert {e["new_state"] for e in warn_or_error["events"]} == {"ERROR", "WARN"}
    assert [e["robot"] for e in laser["events"]] == ["robot10"]
    assert [len(page) for page in pages] == [7, 7, 7, 4]
    ids = [e["id"] for page in pages for e in page]
    assert ids == sorted(ids, reverse=True) and len(set(ids)) == 25
    assert len(since["events"]) == 26 and nothing["events"] == []


@pytest.mark.parametrize(
    ("query", "parameter"),
    [
        ("robot=", "robot"),
        ("level=BROKEN", "level"),
        ("level=ERROR,", "level"),
        ("since=yesterday", "since"),
        ("since=2026-11-23T08:00:00", "since"),  # no offset: ambiguous
        ("until=nan", "until"),
        ("since=200&until=100", "until"),
        ("limit=0", "limit"),
        ("limit=1001", "limit"),
        ("limit=ten", "limit"),
        ("before=bm9wZQ", "before"),
        ("before=%00", "before"),
        ("robots=robot1", "robots"),
        ("robot=a&robot=b", "robot"),
    ],
)
def test_a_bad_parameter_is_a_400_naming_it(tmp_path: Path, query: str, parameter: str) -> None:
    with exporter(tmp_path) as running:
        status, document = get(running, "/api/v1/events?" + query)
    assert status == 400
    assert document["error"].startswith(parameter + ":"), document


def test_disabled_history_is_a_404_and_has_no_metrics(tmp_path: Path) -> None:
    with exporter(tmp_path, events={"enabled": False}) as running:
        status, document = get(running, "/api/v1/events")
        with urllib.request.urlopen(running.server.url + "/metrics", timeout=5) as response:
            exposition = response.read()
    assert status == 404 and "disabled" in document["error"]
    assert b"overseer_events_" not in exposition
    assert not (tmp_path / "events.db").exists()


def test_an_unusable_database_is_a_503_while_metrics_go_on(tmp_path: Path) -> None:
    (tmp_path / "events.db").write_bytes(b"\x00garbage" * 1000)
    with exporter(tmp_path) as running:
        publish(running, "robot1", (2, "/a", "broken"))
        status, document = get(running, "/api/v1/events")
        with urllib.request.urlopen(running.server.url + "/metrics", timeout=5) as response:
            exposition = response.read().decode()
        robots = get(running, "/api/v1/robots")
    assert status == 503 and "events.db" in document["error"]
    assert "overseer_events_store_up 0.0" in exposition
    assert 'overseer_events_dropped_total{reason="store_unavailable"} 1.0' in exposition
    assert 'ros_diagnostics_level{component="/a",hardware_id="hw",robot="robot1"} 2.0' in exposition
    assert robots[0] == 200


def test_metrics_carry_the_event_counts_byte_identical_to_prometheus_client(tmp_path: Path) -> None:
    with exporter(tmp_path) as running:
        publish(running, "robot1", (0, "/a", "ok"), (1, "/b", "warm"))
        publish(running, "robot1", (2, "/a", "bad"), (1, "/b", "warm"))
        assert running.model is not None and running.history is not None
        oracle = OracleCollector(running.model, re.compile(".*"), enabled_transports(running.config))
        maintenance = MaintenanceOracle(running.maintenance, running.fleet.robot_names)
        assert running.render_ahead is not None  # on by default: its metrics come before maintenance
        render_timing = RenderTimingCollector(running.server.render_timing)
        render_ahead = RenderAheadCollector(running.render_ahead)
        registry = oracle_registry(
            oracle, running.history.collector, render_timing, render_ahead, maintenance
        )
        assembler, fleet = running.server.assembler, running.fleet
        for fmt in (TEXT, OPENMETRICS):
            fast = assembler.assemble(fleet.exposition_parts(), fmt)
            assert fast == (oracle_openmetrics(registry) if fmt.openmetrics else oracle_text(registry))
        fast = assembler.assemble(fleet.exposition_parts(), TEXT)
    text = fast.decode()
    assert "overseer_events_written_total 3.0" in text
    assert re.search(r"^overseer_events_database_bytes [1-9][0-9.e+]*$", text, re.MULTILINE)
    assert text.index("overseer_build_info") < text.index("overseer_events_written_total")


def test_basic_auth_guards_the_events_too(tmp_path: Path) -> None:
    password_hash = bcrypt.hashpw(b"secret", bcrypt.gensalt(rounds=4)).decode()
    web_config = tmp_path / "web.yml"
    web_config.write_text(f"basic_auth_users:\n  ops: '{password_hash}'\n")
    with exporter(tmp_path, web={"config_file": str(web_config)}) as running:
        publish(running, "robot1", (2, "/a", "broken"))
        refused, _ = get(running, "/api/v1/events")
        good = {"Authorization": "Basic " + b64encode(b"ops:secret").decode()}
        status, document = get(running, "/api/v1/events?robot=" + quote("robot1"), good)
    assert refused == 401
    assert status == 200 and [e["message"] for e in document["events"]] == ["broken"]


def test_head_answers_like_get_without_a_body(tmp_path: Path) -> None:
    with exporter(tmp_path) as running:
        request = urllib.request.Request(running.server.url + "/api/v1/events", method="HEAD")
        with urllib.request.urlopen(request, timeout=5) as response:
            assert response.status == 200 and response.read() == b""
            assert response.headers["Content-Type"].startswith("application/json")
