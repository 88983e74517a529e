"""The fleet's robot names, which every scrape's maintenance series are written for, without documents.

The names must be the robots `GET /api/v1/robots` lists: heard, listed but never heard, down. The
exporter's workers answer them in `test_ingest_workers.py`, through a real exporter's `/metrics`.
"""

from __future__ import annotations

import re

from overseer.fleet.exposition import FleetExposition
from overseer.fleet.local import LocalFleet
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel, Inventory, ListedRobot

START = 1_700_000_000.0


def test_the_names_are_the_robots_the_robots_document_lists() -> None:
    now = [START]
    model = FleetModel(FleetLimits(stale_after=5.0, robot_timeout=10.0), clock=lambda: now[0])
    fleet = LocalFleet(model, [], FleetExposition(model, re.compile(".*")))
    statuses = (DiagnosticStatus(0, "motor", "fine", "hw"),)
    for robot in ("quiet", 'hostile "name"\n', "busy"):
        model.apply(robot, DiagnosticArray(0, 0, "", statuses), "dds", feed="writer")
    now[0] += 20.0  # all three down, still followed
    model.apply("busy", DiagnosticArray(0, 0, "", statuses), "dds", feed="writer")
    model.set_inventory(Inventory({"never_heard": ListedRobot((), ())}))
    listed = [robot["robot"] for robot in fleet.robots_document()["robots"]]
    assert sorted(fleet.robot_names()) == listed
    assert set(listed) == {"quiet", 'hostile "name"\n', "busy", "never_heard"}
