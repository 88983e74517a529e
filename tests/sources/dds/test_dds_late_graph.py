"""Writers of the absolute /diagnostics whose node the ROS graph tells only after the grace (DDS, --ros2).

Fast DDS sends a reader that matched after the graph was written that graph at its next heartbeat, up to
3 s later, and a lost heartbeat makes it 6 s: the exporter then takes the writer for its domain's robot
for a while. When the graph names the node, the writer must move to its node's robot, and a robot that
was only ever that writer must go, as an event and a count, not linger down and alert as a robot.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from overseer.codec.cdr import encode_diagnostic_array
from overseer.codec.discovery_info import NodeEntities
from overseer.messages import DiagnosticArray, DiagnosticStatus
from testbed.dds_writer import RawDiagnosticsWriter, raw_diagnostics_writer, ros_graph_writer
from testbed.processes import Exporter, running_exporter, wait_for
from testbed.ros2 import ros2_environment

pytestmark = pytest.mark.servers

LATE = DiagnosticStatus(1, "late_node: Battery", "low", "b1", ())
PLAIN = DiagnosticStatus(0, "Disk", "ok", "host", ())


def heard(exporter: Exporter, robot: str, writers: dict[RawDiagnosticsWriter, DiagnosticStatus]) -> bool:
    """Each writer writes its status again; True when `robot` is up with exactly these components."""
    for writer, status in writers.items():
        writer.write(encode_diagnostic_array(DiagnosticArray(0, 0, "", (status,))))
    document = exporter.robot(robot)
    names = {component["name"] for component in (document or {}).get("components", [])}
    return document is not None and document["up"] and names == {status.name for status in writers.values()}


def robot_names(exporter: Exporter) -> set[str]:
    return {robot["robot"] for robot in exporter.get_json("/api/v1/robots")["robots"]}


def event_kinds(exporter: Exporter, robot: str) -> list[str]:
    events: list[dict[str, Any]] = exporter.get_json(f"/api/v1/events?robot={robot}&limit=100")["events"]
    return [event["kind"] for event in events[::-1]]


def exporter_for(tmp_path: Path, domain: int, source: str) -> Any:
    """The exporter on `domain` through the DDS source (with 1 or 2 ingest workers) or --ros2."""
    if source == "ros2":
        return running_exporter(
            tmp_path, None, "--ros2", "--ingest.workers=1", env=ros2_environment(domain), loopback_flag=False
        )
    return running_exporter(tmp_path, domain, f"--ingest.workers={source[-1]}")


@pytest.mark.parametrize("source", ["dds-workers-1", "dds-workers-2", "ros2"])
def test_a_writer_whose_node_is_told_late_moves_to_its_robot_and_the_domains_robot_goes(
    tmp_path: Path, dds_domain: int, source: str
) -> None:
    domain_robot = f"domain{dds_domain}"
    with (
        exporter_for(tmp_path, dds_domain, source) as exporter,
        raw_diagnostics_writer(dds_domain, "rt/diagnostics") as writer,
        ros_graph_writer(dds_domain) as graph,
    ):
        wait_for(lambda: heard(exporter, domain_robot, {writer: LATE}), 30, 0.5, "the domain's robot first")
        wait_for(
            lambda: "robot_up" in event_kinds(exporter, domain_robot), 10, message="it is up in the history"
        )
        graph.announce(NodeEntities("/robot_late", "late_node", (writer.guid,)))
        wait_for(
            lambda: heard(exporter, "robot_late", {writer: LATE}) and robot_names(exporter) == {"robot_late"},
            30,
            0.5,
            "the node's robot alone",
        )
        wait_for(lambda: "reattributed" in event_kinds(exporter, domain_robot), 10, message="its event")
        forgotten = exporter.samples()["overseer_robots_forgotten_total"]
        kinds = event_kinds(exporter, domain_robot)
        robot_late_kinds = event_kinds(exporter, "robot_late")
    assert forgotten[(("reason", "reattributed"),)] == 1
    assert kinds == ["appeared", "robot_up", "reattributed"]
    assert robot_late_kinds == ["appeared", "robot_up"]


def test_the_domains_robot_keeps_what_its_other_writers_say(tmp_path: Path, dds_domain: int) -> None:
    domain_robot = f"domain{dds_domain}"
    with (
        running_exporter(tmp_path, dds_domain, "--ingest.workers=1") as exporter,
        raw_diagnostics_writer(dds_domain, "rt/diagnostics") as writer,
        raw_diagnostics_writer(dds_domain, "rt/diagnostics") as plain,
        ros_graph_writer(dds_domain) as graph,
    ):
        both = {writer: LATE, plain: PLAIN}
        wait_for(lambda: heard(exporter, domain_robot, both), 30, 0.5, "both writers, the domain's robot")
        graph.announce(NodeEntities("/robot_late", "late_node", (writer.guid,)))
        wait_for(
            lambda: (
                heard(exporter, "robot_late", {writer: LATE})
                and heard(exporter, domain_robot, {plain: PLAIN})
            ),
            30,
            0.5,
            "each writer's own robot",
        )
        forgotten = exporter.samples()["overseer_robots_forgotten_total"]
        kinds = event_kinds(exporter, domain_robot)
    assert forgotten[(("reason", "reattributed"),)] == 0
    assert "robot_down" not in kinds and "reattributed" not in kinds
