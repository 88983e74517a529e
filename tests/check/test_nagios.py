"""The shipped Nagios definitions (deploy/nagios) on a real Nagios 4, checking a live exporter.

Nagios loads the shipped files themselves plus a test-only objects file; $USER1$ points at this
environment's check_ros_diagnostics, and interval_length=1 turns the shipped minutes into seconds.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from support.check_cases import CASES, CheckCase, assert_matches_golden
from testbed.nagios import (
    Nagios,
    PluginResult,
    running_fleet,
    running_nagios,
    validate_nagios_config,
    write_nagios_config,
)
from testbed.ports import fresh_domain_id
from testbed.processes import wait_for

# What a site has besides our files: the sample config's 24x7 period and a contact.
SITE_OBJECTS = """
define timeperiod {
    timeperiod_name     24x7
    alias               24 hours a day, 7 days a week
    sunday              00:00-24:00
    monday              00:00-24:00
    tuesday             00:00-24:00
    wednesday           00:00-24:00
    thursday            00:00-24:00
    friday              00:00-24:00
    saturday            00:00-24:00
}
define command {
    command_name        notify-nobody
    command_line        /bin/true
}
define contact {
    contact_name                    nobody
    host_notifications_enabled      0
    service_notifications_enabled   0
    host_notification_period        24x7
    service_notification_period     24x7
    host_notification_options       n
    service_notification_options    n
    host_notification_commands      notify-nobody
    service_notification_commands   notify-nobody
}
"""


def robot_hosts(exporter_url: str) -> str:
    """Hosts robot1..robot4 as an operator would define them, each with every shipped subsystem service."""
    objects = [SITE_OBJECTS]
    for number in (1, 2, 3, 4):
        objects.append(
            f"""define host {{
    use                 ros-robot
    host_name           robot{number}
    address             127.0.0.1
    max_check_attempts  1
    _ROS_ROBOT          robot{number}
    _ROS_EXPORTER_URL   {exporter_url}
}}
"""
        )
        objects.extend(
            f"define service {{\n    use {template}\n    host_name robot{number}\n}}\n"
            for template in ("ros-battery", "ros-motor", "ros-temperature")
        )
    return "\n".join(objects)


def test_nagios_accepts_the_shipped_definitions(tmp_path: Path) -> None:
    done = validate_nagios_config(write_nagios_config(tmp_path, robot_hosts("http://127.0.0.1:9849")))
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Total Errors:   0" in done.stdout
    assert "Checked 16 services." in done.stdout


def test_nagios_rejects_a_robot_without_its_site_objects(tmp_path: Path) -> None:
    objects = robot_hosts("http://127.0.0.1:9849").replace(SITE_OBJECTS, "")
    done = validate_nagios_config(write_nagios_config(tmp_path, objects))
    assert done.returncode != 0
    assert "24x7" in done.stdout


@pytest.fixture(scope="module")
def nagios(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Nagios]:
    """Nagios with the shipped definitions, checking robots of a live exporter fed by the simulator."""
    with (
        running_fleet(tmp_path_factory.mktemp("fleet"), fresh_domain_id()) as exporter,
        running_nagios(tmp_path_factory.mktemp("nagios"), robot_hosts(exporter.url)) as server,
    ):
        yield server


def settled_result(nagios: Nagios, host: str, service: str, state: int) -> PluginResult | None:
    """The service's last result once it is in `state`."""
    result = nagios.services().get((host, service))
    return result if result is not None and result.state == state else None


@pytest.mark.servers
@pytest.mark.parametrize("case", CASES, ids=[case.golden for case in CASES])
def test_nagios_reports_what_the_check_reports(nagios: Nagios, case: CheckCase) -> None:
    try:
        result = wait_for(
            lambda: settled_result(nagios, case.robot, case.nagios_service, case.state),
            timeout=60,
            interval=0.5,
            message=f"{case.robot};{case.nagios_service} in state {case.state}",
        )
    except AssertionError as error:
        last = nagios.services().get((case.robot, case.nagios_service))
        raise AssertionError(f"{error}\nlast result: {last}\n{nagios.log()}") from None
    assert_matches_golden(case.golden, result)


@pytest.mark.servers
def test_nagios_runs_every_subsystem_service(nagios: Nagios) -> None:
    wanted = {"ROS diagnostics", "ROS batteries", "ROS motors", "ROS temperatures"}
    wait_for(
        lambda: {service for host, service in nagios.services() if host == "robot1"} == wanted,
        timeout=60,
        message="every robot1 service checked",
    )
    assert nagios.services()[("robot1", "ROS temperatures")] == PluginResult(
        0,
        "OK - robot1: 3 components OK | 'error'=0;;;0 'warn'=0;;;0 'stale'=0;;;0 'ok'=3;;;0\n"
        "OK sensor(s) list:\n/Temp: OK\n/Temp/Sensor1 [temp1]: Normal\n/Temp/Sensor2 [temp2]: Normal",
    )
