"""check_ros_diagnostics against a real exporter fed by the simulated fleet over loopback DDS."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from support.check_cases import CASES, CheckCase, assert_matches_golden
from testbed.nagios import check_until, run_check, running_fleet
from testbed.ports import fresh_domain_id
from testbed.processes import Exporter

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Exporter]:
    """The exporter, once every robot of the fleet is in the state its case expects."""
    with running_fleet(tmp_path_factory.mktemp("fleet"), fresh_domain_id()) as exporter:
        yield exporter


def port_of(exporter: Exporter) -> str:
    """The exporter's port, for -p."""
    return exporter.url.rsplit(":", 1)[1]


@pytest.mark.parametrize("case", CASES, ids=[case.golden for case in CASES])
def test_check_reports_the_robots_state(fleet: Exporter, case: CheckCase) -> None:
    args = ("-H", "127.0.0.1", "-p", port_of(fleet), "-r", case.robot, "-n", case.name_filter)
    assert_matches_golden(case.golden, check_until(case.state, *args))


def test_check_agrees_with_the_exporters_robot_level(fleet: Exporter) -> None:
    robots = fleet.get_json("/api/v1/robots")["robots"]
    for robot in robots:
        state = run_check("--url", fleet.url, "-r", robot["robot"]).state
        assert state == robot["level"], robot


def test_unknown_robot_is_unknown_and_says_so(fleet: Exporter) -> None:
    assert_matches_golden("unknown_robot", check_until(3, "--url", fleet.url, "-r", "robot9"))


def test_filter_that_matches_nothing_is_unknown(fleet: Exporter) -> None:
    result = check_until(3, "--url", fleet.url, "-r", "robot3", "-n", "gripper")
    assert_matches_golden("filter_matches_nothing", result)


def test_stale_state_critical_turns_a_down_robot_critical(fleet: Exporter) -> None:
    result = check_until(2, "--url", fleet.url, "-r", "robot4", "--stale-state=critical")
    assert_matches_golden("robot_down_stale_critical", result)


def test_stale_state_warning_ranks_below_a_real_warning(fleet: Exporter) -> None:
    only_leaves = "--name-regex=^/(Temp|Camera)/"
    result = check_until(1, "--url", fleet.url, "-r", "robot2", "--stale-state=warning", only_leaves)
    assert_matches_golden("stale_as_warning", result)


def test_regex_filter_and_perfdata_values(fleet: Exporter) -> None:
    result = check_until(
        1, "--url", fleet.url, "-r", "robot3", "--name-regex=Battery$", "--perfdata-values", "-v"
    )
    assert_matches_golden("battery_regex_with_values", result)
