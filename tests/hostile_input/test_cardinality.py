"""Cardinality attacks over real DDS: a component name invented in every message, a thousand robots.

The caps hold, the exporter's memory stays flat once they are reached, and every status dropped is
counted in `overseer_statuses_dropped_total` and every message that lost anything in
`overseer_messages_total{result="dropped"}`, which the shipped alerts OverseerDroppingStatuses and
OverseerDroppingMessages watch.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from prometheus_client.parser import text_string_to_metric_families

from bench.common import tree_resident_bytes
from overseer.codec.cdr import encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from testbed.dds_writer import raw_diagnostics_writer
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


COMPONENT_CAP, NEW_PER_MESSAGE, MESSAGES, RATE_HZ = 1000, 5, 2600, 75.0
CAP_CHECK_AT = 2 * COMPONENT_CAP // NEW_PER_MESSAGE  # twice the names the cap holds have been offered
SETTLED_AT = 800  # past the kept components' STALE timeout (5 s) and its events: 10.7 s at RATE_HZ
ROBOT_CAP, ROBOTS = 100, 1000
FLAT_MEMORY_BYTES = 4 * 1024 * 1024  # keeping the 9,000 statuses dropped after SETTLED_AT would take 10 MiB


def resident_bytes(exporter: Exporter) -> int:
    """The resident memory of the exporter's process and its ingest workers, summed."""
    return tree_resident_bytes(exporter.process.pid)


def memory_after_a_scrape(exporter: Exporter) -> int:
    """The exporter's resident memory right after it rendered /metrics (as at every other reading)."""
    counters(exporter)
    return resident_bytes(exporter)


def counters(exporter: Exporter) -> dict[str, float]:
    """The exporter's drop and message counters, from /metrics, as `name{label}` → value."""
    found = {}
    for family in text_string_to_metric_families(exporter.get("/metrics").decode()):
        for sample in family.samples:
            if sample.name == "overseer_messages_total":
                found[f"messages{{{sample.labels['result']}}}"] = sample.value
            elif sample.name == "overseer_statuses_dropped_total":
                found[f"dropped{{{sample.labels['reason']}}}"] = sample.value
            elif sample.name == "overseer_events_written_total":
                found["events{written}"] = sample.value
    return found


def churn_message(index: int) -> bytes:
    """Message `index`: NEW_PER_MESSAGE components never seen before, with long names and messages."""
    statuses = tuple(
        DiagnosticStatus(
            index % 3, f"/Churn/{index:06d}/{j}/" + "n" * 150, "m" * 500, f"hw{index}", (("v", "1"),)
        )
        for j in range(NEW_PER_MESSAGE)
    )
    return encode_diagnostic_array(DiagnosticArray(index, 0, "", statuses))


def components_of(exporter: Exporter, robot: str) -> int:
    """How many components the exporter keeps for `robot`."""
    for summary in exporter.get_json("/api/v1/robots")["robots"]:
        if summary["robot"] == robot:
            return sum(summary["counts"].values())
    return -1


def test_a_new_component_name_in_every_message_hits_the_cap_counted_with_flat_memory(
    tmp_path: Path, dds_domain: int
) -> None:
    """Past the cap and once the kept components' events are written, the exporter's memory stays flat.

    The kept components are never updated again, so 5 s after their one status they go STALE and the
    event history records 1,000 more events; its SQLite page cache (bounded) grows with them. Memory is
    measured flat from then on, while 9,000 more statuses are dropped.
    """
    with (
        running_exporter(tmp_path, dds_domain, "--log.level=warning") as exporter,
        raw_diagnostics_writer(dds_domain, "rt/churn/diagnostics_agg") as writer,
    ):
        wait_for(lambda: exporter.robot("churn"), 30, message="the churning robot discovered")
        writer.wait_for_reader()
        started = time.monotonic()
        memory_at_cap = memory_settled = memory_at_end = 0
        for index in range(MESSAGES):
            assert writer.write(churn_message(index)) >= 0
            if index == CAP_CHECK_AT:
                wait_for(lambda: components_of(exporter, "churn") == COMPONENT_CAP, 10, message="the cap")
                memory_at_cap = resident_bytes(exporter)
            elif index == SETTLED_AT:
                wait_for(
                    lambda: counters(exporter).get("events{written}", 0) >= 2 * COMPONENT_CAP,
                    30,
                    message="every kept component's arrival and STALE recorded",
                )
                memory_settled = memory_after_a_scrape(exporter)
            elif index == MESSAGES - 1:
                memory_at_end = memory_after_a_scrape(exporter)
            if index in (CAP_CHECK_AT, SETTLED_AT):  # go on at RATE_HZ rather than catching up in a burst
                started = time.monotonic() - (index + 1) / RATE_HZ
            time.sleep(max(0.0, started + (index + 1) / RATE_HZ - time.monotonic()))

        def all_counted() -> dict[str, float] | None:
            found = counters(exporter)
            return found if found["messages{received}"] + found["messages{dropped}"] == MESSAGES else None

        found = wait_for(all_counted, 30, message="every message counted")
        components = components_of(exporter, "churn")
        body = exporter.get("/metrics")

    fitted = COMPONENT_CAP // NEW_PER_MESSAGE  # the first messages fit whole; every later one lost all
    print(
        f"\ncomponent churn: {MESSAGES} messages, {MESSAGES * NEW_PER_MESSAGE} distinct names; "
        f"kept {components}; dropped {found['dropped{component_limit}']:.0f} statuses "
        f"in {found['messages{dropped}']:.0f} messages; RSS {memory_at_cap / 2**20:.1f} MiB at the cap, "
        f"{memory_settled / 2**20:.1f} MiB with its events written, "
        f"{memory_at_end / 2**20:.1f} MiB at the end"
    )
    assert components == COMPONENT_CAP
    assert found["messages{received}"] == fitted
    assert found["messages{dropped}"] == MESSAGES - fitted
    assert found["dropped{component_limit}"] == (MESSAGES - fitted) * NEW_PER_MESSAGE
    assert found["messages{decode_error}"] == 0
    assert memory_at_end - memory_settled < FLAT_MEMORY_BYTES, (
        f"memory grew by {(memory_at_end - memory_settled) / 2**20:.1f} MiB "
        f"while {(MESSAGES - SETTLED_AT - 1) * NEW_PER_MESSAGE} statuses were dropped"
    )
    assert body.count(b'ros_diagnostics_level{component="/Churn/') == COMPONENT_CAP


def test_a_thousand_robots_against_a_cap_of_a_hundred(tmp_path: Path, dds_domain: int) -> None:
    config = tmp_path / "overseer.yml"
    config.write_text(f"fleet:\n  max_robots: {ROBOT_CAP}\n")
    with (
        running_exporter(tmp_path, dds_domain, f"--config.file={config}", "--log.level=error") as exporter,
        running_simulator(tmp_path, dds_domain, f"--robots={ROBOTS}", "--components=5", "--rate=1"),
    ):

        def capped() -> dict[str, float] | None:
            found = counters(exporter)
            refused = found["dropped{robot_limit}"] >= ROBOTS - ROBOT_CAP
            return (
                found if refused and len(exporter.get_json("/api/v1/robots")["robots"]) == ROBOT_CAP else None
            )

        wait_for(capped, 120, interval=1.0, message="the robot cap reached, the rest refused")
        memory_at_cap = resident_bytes(exporter)
        time.sleep(15)
        found = counters(exporter)
        memory_at_end = resident_bytes(exporter)
        robots = exporter.get_json("/api/v1/robots")["robots"]
        body = exporter.get("/metrics").decode()

    growth = memory_at_end - memory_at_cap
    print(
        f"\nrobot flood: {ROBOTS} robots, kept {len(robots)}, refused {found['dropped{robot_limit}']:.0f}; "
        f"RSS {memory_at_cap / 2**20:.1f} MiB at the cap, {memory_at_end / 2**20:.1f} MiB 15 s later"
    )
    assert len(robots) == ROBOT_CAP
    assert all(robot["up"] for robot in robots)  # the robots it follows are served as usual
    assert body.count("ros_diagnostics_robot_up{") == ROBOT_CAP
    assert found["dropped{robot_limit}"] >= ROBOTS - ROBOT_CAP
    assert found["messages{decode_error}"] == 0
    assert growth < FLAT_MEMORY_BYTES, f"memory grew by {growth / 2**20:.1f} MiB after the cap"
