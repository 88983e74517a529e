"""GET /api/v1/components: the fleet-wide component search the status page reads, pure and over HTTP."""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from collections.abc import Iterator
from typing import Any

import pytest

from overseer.fleet.documents import (
    COMPONENTS_MAX_LIMIT,
    ComponentQuery,
    components_document,
    robots_document,
)
from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.serve.api_query import ApiQueryError, parse_component_query
from overseer.serve.http import OverseerServer
from support.clock import ManualClock
from testbed.model_server import serving


def array(*statuses: tuple[int, str, str, str]) -> DiagnosticArray:
    """A message of (level, name, message, hardware_id) statuses."""
    return DiagnosticArray(0, 0, "", tuple(DiagnosticStatus(*s, ()) for s in statuses))


@pytest.fixture
def fleet() -> tuple[FleetModel, ManualClock]:
    """Three robots: site_a/r1 failing its laser, site_a/r2 warning, robot3 all OK."""
    clock = ManualClock()
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=30), clock=clock)
    for second in range(2):  # twice, a second apart: every robot's period is known
        clock.now += second
        model.apply(
            "site_a/r1",
            array((2, "/Laser/Front", "No scans received", "sick1"), (0, "/Power/Battery", "Charge OK", "")),
            "dds",
        )
        model.apply(
            "site_a/r2",
            array((1, "/Power/Battery", "Low charge", "bms2"), (0, "/Laser/Front", "Scanning", "")),
            "dds",
        )
        model.apply(
            "robot3",
            array((0, "/Power/Battery", "Charge OK", ""), (0, "/Camera/Cam1", "Streaming", "")),
            "dds",
        )
    return model, clock


def found(document: dict[str, Any]) -> list[tuple[str, str, str]]:
    return [(c["robot"], c["name"], c["state"]) for c in document["components"]]


def test_no_filter_lists_every_component_worst_first_then_by_robot_and_name(
    fleet: tuple[FleetModel, ManualClock],
) -> None:
    document = components_document(fleet[0].snapshot(), ComponentQuery())
    assert found(document) == [
        ("site_a/r1", "/Laser/Front", "ERROR"),
        ("site_a/r2", "/Power/Battery", "WARN"),
        ("robot3", "/Camera/Cam1", "OK"),
        ("robot3", "/Power/Battery", "OK"),
        ("site_a/r1", "/Power/Battery", "OK"),
        ("site_a/r2", "/Laser/Front", "OK"),
    ]
    assert (document["total"], document["truncated"]) == (6, False)
    first = document["components"][0]
    assert first == {
        "robot": "site_a/r1",
        "name": "/Laser/Front",
        "hardware_id": "sick1",
        "level": 2,
        "state": "ERROR",
        "message": "No scans received",
        "last_update": 1_700_000_001.0,
        "reported": True,
    }


def test_level_filter_uses_the_level_now_stale_included(fleet: tuple[FleetModel, ManualClock]) -> None:
    model, clock = fleet
    clock.now += 6  # every component is stale now: reported ERROR and WARN no longer count as such
    model.apply(
        "robot3", array((0, "/Power/Battery", "Charge OK", ""), (0, "/Camera/Cam1", "Streaming", "")), "dds"
    )
    snapshot = model.snapshot()
    assert found(components_document(snapshot, ComponentQuery(levels=frozenset({Level.ERROR})))) == []
    stale = components_document(snapshot, ComponentQuery(levels=frozenset({Level.STALE})))
    assert {(robot, name) for robot, name, _ in found(stale)} == {
        ("site_a/r1", "/Laser/Front"),
        ("site_a/r1", "/Power/Battery"),
        ("site_a/r2", "/Power/Battery"),
        ("site_a/r2", "/Laser/Front"),
    }
    assert {state for _, _, state in found(stale)} == {"STALE"}


def test_text_matches_robot_component_hardware_id_and_message_ignoring_case(
    fleet: tuple[FleetModel, ManualClock],
) -> None:
    snapshot = fleet[0].snapshot()

    def search(text: str) -> set[tuple[str, str]]:
        return {(r, n) for r, n, _ in found(components_document(snapshot, ComponentQuery(text=text)))}

    assert search("NO SCANS") == {("site_a/r1", "/Laser/Front")}  # message
    assert search("cam1") == {("robot3", "/Camera/Cam1")}  # component name
    assert search("BMS2") == {("site_a/r2", "/Power/Battery")}  # hardware_id
    assert search("robot3") == {("robot3", "/Camera/Cam1"), ("robot3", "/Power/Battery")}  # robot name
    assert search("nothing like it") == set()


def test_text_folds_case_beyond_ascii_and_never_matches_across_two_texts() -> None:
    """A robot's texts are searched joined at first; only a text that has the needle itself matches."""
    model = FleetModel(FleetLimits())
    model.apply("werk/r1", array((1, "/Tür/Sensor", "Straße blockiert", "GROSS-1")), "dds")
    model.apply("werk/r2", array((0, "/Motor", "läuft", ""), (0, "/Gate", "open", "")), "dds")
    model.apply("werk/r3", array((0, "/Pump", "MASSE OK", "")), "dds")  # ASCII only
    snapshot = model.snapshot()

    def search(text: str, levels: frozenset[Level] | None = None) -> set[tuple[str, str]]:
        query = ComponentQuery(text=text, levels=levels)
        return {(r, n) for r, n, _ in found(components_document(snapshot, query))}

    assert search("STRASSE") == {("werk/r1", "/Tür/Sensor")}  # ß folds to ss
    assert search("groß") == {("werk/r1", "/Tür/Sensor")}  # and the needle's too, in a hardware_id
    assert search("maße") == {("werk/r3", "/Pump")}
    assert search("TÜR") == {("werk/r1", "/Tür/Sensor")}
    assert search("LÄUFT", frozenset({Level.OK})) == {("werk/r2", "/Motor")}
    # "/Motor" and "/Gate" are neighbours among the robot's names, but no one text holds both
    assert search("motor\n/gate") == set()
    assert search("läuft\nopen") == set()


def test_robots_list_every_robot_with_a_match_and_how_many(fleet: tuple[FleetModel, ManualClock]) -> None:
    document = components_document(fleet[0].snapshot(), ComponentQuery(text="battery", limit=1))
    assert document["robots"] == [
        {"robot": "robot3", "matches": 1},
        {"robot": "site_a/r1", "matches": 1},
        {"robot": "site_a/r2", "matches": 1},
    ]
    assert found(document) == [("site_a/r2", "/Power/Battery", "WARN")]  # the worst survives the limit
    assert (document["total"], document["limit"], document["truncated"]) == (3, 1, True)


def test_robot_and_levels_combine(fleet: tuple[FleetModel, ManualClock]) -> None:
    query = ComponentQuery(levels=frozenset({Level.OK, Level.WARN}), robot="site_a/r2")
    assert found(components_document(fleet[0].snapshot(), query)) == [
        ("site_a/r2", "/Power/Battery", "WARN"),
        ("site_a/r2", "/Laser/Front", "OK"),
    ]


def test_query_parameters_are_parsed_from_names_numbers_and_lists() -> None:
    query = parse_component_query(
        {"level": ["error,Warn", "3"], "q": ["laser"], "limit": ["7"], "robot": ["a/b"]}
    )
    assert query == ComponentQuery(frozenset({Level.ERROR, Level.WARN, Level.STALE}), "laser", "a/b", 7)
    assert parse_component_query({}) == ComponentQuery()


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"level": ["ERROR,BAD"]}, "level: expected OK, WARN, ERROR, STALE or 0-3, got 'BAD'"),
        ({"level": ["4"]}, "level: expected OK, WARN, ERROR, STALE or 0-3, got '4'"),
        ({"limit": ["0"]}, f"limit: expected a whole number from 1 to {COMPONENTS_MAX_LIMIT}, got '0'"),
        ({"limit": ["1001"]}, f"limit: expected a whole number from 1 to {COMPONENTS_MAX_LIMIT}, got '1001'"),
        ({"limit": ["ten"]}, f"limit: expected a whole number from 1 to {COMPONENTS_MAX_LIMIT}, got 'ten'"),
        ({"q": ["x" * 257]}, "q: longer than 256 characters (257)"),
    ],
)
def test_bad_parameters_are_refused_naming_the_parameter_and_value(
    params: dict[str, list[str]], message: str
) -> None:
    with pytest.raises(ApiQueryError) as raised:
        parse_component_query(params)
    assert str(raised.value) == message


@pytest.fixture
def server(fleet: tuple[FleetModel, ManualClock]) -> Iterator[OverseerServer]:
    """The real HTTP server over the fleet, on a free loopback port."""
    with serving(fleet[0]) as server:
        yield server


def get(server: OverseerServer, path: str) -> tuple[int, Any]:
    try:
        with urllib.request.urlopen(server.url + path, timeout=10) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read())


def test_http_route_answers_the_search_and_refuses_bad_input_with_400(server: OverseerServer) -> None:
    status, document = get(server, "/api/v1/components?level=ERROR,WARN&q=site_a%2Fr&limit=5")
    assert status == 200
    assert found(document) == [
        ("site_a/r1", "/Laser/Front", "ERROR"),
        ("site_a/r2", "/Power/Battery", "WARN"),
    ]
    status, document = get(server, "/api/v1/components?level=CRITICAL")
    assert (status, document) == (
        400,
        {"error": "level: expected OK, WARN, ERROR, STALE or 0-3, got 'CRITICAL'"},
    )
    status, document = get(server, "/api/v1/components?limit=100000")
    assert status == 400 and document["error"].startswith("limit:")
    status, _ = get(server, "/api/v1/robots")
    assert status == 200  # the server keeps serving after refusing


def test_the_page_files_are_served_with_their_types_and_a_strict_policy(server: OverseerServer) -> None:
    for path, content_type in [
        ("/", "text/html; charset=utf-8"),
        ("/static/app.js", "text/javascript; charset=utf-8"),
        ("/static/style.css", "text/css; charset=utf-8"),
    ]:
        with urllib.request.urlopen(server.url + path, timeout=10) as response:
            assert response.headers["Content-Type"] == content_type
            assert "script-src 'self'" in response.headers["Content-Security-Policy"]
            assert response.read()
    status, document = get(server, "/static/../api.py")
    assert status == 404 and "no such path" in document["error"]
    status, _ = get(server, "/static/nothing.js")
    assert status == 404


def test_fleet_summary_counts_levels_now_and_ranks_the_robot_by_severity() -> None:
    clock = ManualClock()
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=30), clock=clock)
    model.apply("mixed", array((1, "/a", "", ""), (2, "/b", "", "")), "dds")
    model.apply("gone", array((2, "/a", "", "")), "dds")
    clock.now += 1
    model.apply("mixed", array((1, "/a", "", ""), (2, "/b", "", "")), "dds")  # its period is known: 1 s
    clock.now += 5
    model.apply("mixed", array((1, "/a", "", "")), "dds")  # /b is missing from it now: STALE, not ERROR
    model.register("silent", "dds")
    clock.now += 25  # gone is down (31 s), mixed is not (25 s) but all its components are stale now
    model.apply("fresh", array((0, "/a", "", ""), (3, "/b", "", "")), "dds")
    summaries = {r["robot"]: r for r in robots_document(model.snapshot())["robots"]}
    assert {name: (r["state"], r["up"], r["counts"]) for name, r in summaries.items()} == {
        "fresh": ("STALE", True, {"ok": 1, "warn": 0, "error": 0, "stale": 1}),
        "gone": ("STALE", False, {"ok": 0, "warn": 0, "error": 0, "stale": 1}),
        "mixed": ("STALE", True, {"ok": 0, "warn": 0, "error": 0, "stale": 2}),
        "silent": ("STALE", False, {"ok": 0, "warn": 0, "error": 0, "stale": 0}),
    }
    clock.now -= 24  # 1 s after mixed's last message: /a WARN fresh, /b stale; WARN outranks STALE
    mixed = next(r for r in robots_document(model.snapshot())["robots"] if r["robot"] == "mixed")
    assert (mixed["level"], mixed["state"], mixed["counts"]) == (
        1,
        "WARN",
        {"ok": 0, "warn": 1, "error": 0, "stale": 1},
    )
