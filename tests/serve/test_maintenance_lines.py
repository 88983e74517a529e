"""The maintenance families written by hand: prometheus-client's bytes, kept only while nothing changes.

Pure: a schedule on a hand-moved clock, robot names from a list, prometheus-client's collector over the
same schedule as the oracle; and the whole exposition through the assembler, plain and gzipped.
"""

from __future__ import annotations

import gzip

import pytest

from overseer.config.maintenance import MaintenanceConfig
from overseer.fleet.deflated import inflate
from overseer.maintenance.schedule import MaintenanceSchedule
from overseer.model.maintenance import RobotSelector
from overseer.serve.assembler import ExpositionAssembler
from overseer.serve.exposition_formats import OPENMETRICS, TEXT, ExpositionFormat
from overseer.serve.maintenance_lines import MaintenanceLines
from support.clock import ManualClock
from support.maintenance_oracle import MaintenanceOracle
from support.oracle import oracle_openmetrics, oracle_registry, oracle_text

HOSTILE = ['a"b', "back\\slash", "new\nline", "ünï/cøde", "site_a/robot7", ""]
FORMATS = [TEXT, OPENMETRICS]


class Fleet:
    """Robot names as a fleet answers them: any order, repeated across ingest workers."""

    def __init__(self, names: list[str]) -> None:
        self.names = names
        self.asked = 0

    def robot_names(self) -> list[str]:
        self.asked += 1
        return list(self.names)


def oracle(schedule: MaintenanceSchedule, fleet: Fleet, fmt: ExpositionFormat) -> bytes:
    """What prometheus-client writes for the same schedule and names (without OpenMetrics' `# EOF`)."""
    registry = oracle_registry(MaintenanceOracle(schedule, fleet.robot_names))
    if not fmt.openmetrics:
        return oracle_text(registry)
    return oracle_openmetrics(registry).removesuffix(b"# EOF\n")


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock(1_800_000_000.0)


@pytest.fixture
def schedule(clock: ManualClock) -> MaintenanceSchedule:
    return MaintenanceSchedule(MaintenanceConfig(), None, clock=clock)


@pytest.mark.parametrize("fmt", FORMATS, ids=["text", "openmetrics"])
def test_every_robot_out_of_maintenance_is_prometheus_clients_bytes(
    schedule: MaintenanceSchedule, fmt: ExpositionFormat
) -> None:
    fleet = Fleet(["robot2", "robot10", *HOSTILE, "robot2"])
    lines = MaintenanceLines(schedule, fleet.robot_names)
    assert lines.text(fmt) == oracle(schedule, fleet, fmt)
    assert inflate(lines.deflated(fmt)) == lines.text(fmt)
    assert lines.text(fmt).count(b"ros_diagnostics_robot_maintenance{") == len(set(fleet.names))


@pytest.mark.parametrize("fmt", FORMATS, ids=["text", "openmetrics"])
def test_robots_in_windows_scheduled_windows_and_their_ends_are_prometheus_clients_bytes(
    schedule: MaintenanceSchedule, clock: ManualClock, fmt: ExpositionFormat
) -> None:
    fleet = Fleet(["site_a/robot1", "site_a/robot2", "site_b/robot1", 'a"b'])
    schedule.open(RobotSelector.parse("site_a/"), None, clock.now + 3600.25, "swap", "ops")
    schedule.open(RobotSelector.parse("site_a/robot2"), None, clock.now + 7200, "longer", "ops")
    schedule.open(RobotSelector.parse("site_b/"), clock.now + 600, clock.now + 900, "later", "ops")
    lines = MaintenanceLines(schedule, fleet.robot_names)
    text = lines.text(fmt)
    assert text == oracle(schedule, fleet, fmt)
    assert b'ros_diagnostics_robot_maintenance{robot="site_a/robot2"} 1.0' in text
    assert b'overseer_maintenance_windows{state="scheduled"} 1.0' in text
    assert inflate(lines.deflated(fmt)) == text


def test_the_lines_are_kept_while_nothing_changes(schedule: MaintenanceSchedule) -> None:
    fleet = Fleet([f"robot{index}" for index in range(1000)])
    lines = MaintenanceLines(schedule, fleet.robot_names)
    first, piece = lines.text(TEXT), lines.deflated(TEXT)
    assert lines.text(TEXT) is first and lines.deflated(TEXT) is piece
    assert fleet.asked == 4  # the names are asked for at every scrape: only their lines are kept
    assert lines.text(OPENMETRICS) is not first  # another format, its own lines


def test_a_robot_that_comes_or_goes_changes_the_lines(schedule: MaintenanceSchedule) -> None:
    fleet = Fleet(["robot1", "robot2"])
    lines = MaintenanceLines(schedule, fleet.robot_names)
    before = inflate(lines.deflated(TEXT))
    fleet.names.append("robot3")
    assert b'robot="robot3"' in lines.text(TEXT) and b'robot="robot3"' not in before
    assert inflate(lines.deflated(TEXT)) == lines.text(TEXT) == oracle(schedule, fleet, TEXT)
    fleet.names.remove("robot1")
    assert b'robot="robot1"' not in inflate(lines.deflated(TEXT))


def test_a_robot_replaced_by_another_changes_the_lines(schedule: MaintenanceSchedule) -> None:
    fleet = Fleet(["robot1", "robot2"])
    lines = MaintenanceLines(schedule, fleet.robot_names)
    lines.text(TEXT)
    fleet.names[1] = "robot3"
    assert lines.text(TEXT) == oracle(schedule, fleet, TEXT)


def test_an_empty_fleet_has_the_headers_and_the_counts(schedule: MaintenanceSchedule) -> None:
    fleet = Fleet([])
    lines = MaintenanceLines(schedule, fleet.robot_names)
    for fmt in FORMATS:
        assert lines.text(fmt) == oracle(schedule, fleet, fmt)
        assert lines.text(fmt).count(b"# HELP") == 3


def test_one_window_ending_as_another_starts_changes_the_lines(
    schedule: MaintenanceSchedule, clock: ManualClock
) -> None:
    fleet = Fleet(["robot1", "robot2"])
    first = schedule.open(RobotSelector.parse("robot1"), None, clock.now + 600, "first", "ops")
    lines = MaintenanceLines(schedule, fleet.robot_names)
    assert b'robot="robot1"} 1.0' in inflate(lines.deflated(OPENMETRICS))
    schedule.end(first.key, "ops")
    schedule.open(RobotSelector.parse("robot2"), None, clock.now + 600, "second", "ops")
    # The same robots, one window active, none scheduled: only who is in it, and its end, differ.
    after = inflate(lines.deflated(OPENMETRICS))
    assert b'ros_diagnostics_robot_maintenance{robot="robot2"} 1.0' in after
    assert after == oracle(schedule, fleet, OPENMETRICS)


def test_a_window_that_starts_or_ends_changes_the_lines(
    schedule: MaintenanceSchedule, clock: ManualClock
) -> None:
    fleet = Fleet(["robot1", "robot2"])
    schedule.open(RobotSelector.parse("robot1"), clock.now + 60, clock.now + 120, "soon", "ops")
    lines = MaintenanceLines(schedule, fleet.robot_names)
    scheduled = lines.text(TEXT)
    assert b'ros_diagnostics_robot_maintenance{robot="robot1"} 0.0' in scheduled
    clock.now += 61
    started = lines.text(TEXT)
    assert b'ros_diagnostics_robot_maintenance{robot="robot1"} 1.0' in started
    assert started == oracle(schedule, fleet, TEXT)
    clock.now += 60
    ended = inflate(lines.deflated(TEXT))
    assert b'ros_diagnostics_robot_maintenance{robot="robot1"} 0.0' in ended
    assert b'overseer_maintenance_windows{state="active"} 0.0' in ended
    assert ended == oracle(schedule, fleet, TEXT)


@pytest.mark.parametrize("fmt", FORMATS, ids=["text", "openmetrics"])
def test_the_assembled_exposition_ends_with_them_plain_and_gzipped(
    schedule: MaintenanceSchedule, clock: ManualClock, fmt: ExpositionFormat
) -> None:
    fleet = Fleet(["robot1", 'hostile"}\n'])
    schedule.open(RobotSelector.parse("robot1"), None, clock.now + 60, "now", "ops")
    assembler = ExpositionAssembler(["dds"], rendered=[MaintenanceLines(schedule, fleet.robot_names)])
    plain = assembler.assemble([], fmt)
    assert gzip.decompress(assembler.assemble_gzip([], fmt)) == plain
    expected = oracle(schedule, fleet, fmt) + fmt.end
    assert plain.endswith(expected)
    assert plain.index(b"overseer_build_info") < plain.index(b"ros_diagnostics_robot_maintenance")
