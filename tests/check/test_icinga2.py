"""The shipped Icinga 2 definitions (deploy/icinga2) on a real Icinga 2, checking a live exporter.

Icinga 2 loads the shipped files themselves plus a test-only hosts file; PluginContribDir points at
this environment's check_ros_diagnostics.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from overseer.check.plugin import LONG_OPTIONS
from support.check_cases import CASES, CheckCase, assert_matches_golden
from testbed.icinga2 import Icinga2, icinga2, running_icinga2, write_icinga2_config
from testbed.in_process import in_process_exporter, publish
from testbed.nagios import PluginResult, running_fleet
from testbed.ports import fresh_domain_id
from testbed.processes import wait_for

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


def robot_hosts(exporter_port: int) -> str:
    """Hosts robot1..robot4 as an operator would define them, all with every shipped subsystem.

    robot2 has no vars.ros_robot and an explicit service instead of the apply rule, so the
    CheckCommand must fall back to the host name. A host for site_a gets the site's group service.
    """
    hosts = []
    for number in (1, 2, 3, 4):
        robot_var = "" if number == 2 else f'vars.ros_robot = "robot{number}"'
        hosts.append(
            f"""object Host "robot{number}" {{
	check_command = "dummy"
	{robot_var}
	vars.ros_diagnostics_address = "127.0.0.1"
	vars.ros_diagnostics_port = {exporter_port}
	vars.ros_subsystems = [ "battery", "motor", "temperature" ]
}}
"""
        )
    hosts.append(
        'object Service "ros-diagnostics" {\n\thost_name = "robot2"\n\timport "ros-diagnostics"\n}\n'
    )
    hosts.append(
        f'object Host "site_a" {{\n\tcheck_command = "dummy"\n\tvars.ros_site = "site_a"\n'
        f'\tvars.ros_diagnostics_address = "127.0.0.1"\n\tvars.ros_diagnostics_port = {exporter_port}\n}}\n'
    )
    return "\n".join(hosts)


def validate(root: Path, objects: str) -> str:
    """`icinga2 daemon -C` on the shipped definitions plus `objects`; its output, after asserting success."""
    config = write_icinga2_config(root, objects)
    done = icinga2(root, "daemon", "-C", "-c", str(config))
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    return output


def test_icinga2_accepts_the_shipped_definitions_without_warnings(tmp_path: Path) -> None:
    output = validate(tmp_path, robot_hosts(9849))
    assert not re.search(r"\b(warning|critical)/", output), output
    # 4 robots x (overall + 3 subsystems), robot2 without subsystems, and the site's group service
    assert "Instantiated 14 Services." in output


SITE_HOST = """object Host "site_a" {
	check_command = "dummy"
	vars.ros_site = "site_a"
	vars.ros_diagnostics_url = "%s"
}
"""


def test_a_site_host_gets_one_service_that_judges_the_sites_robots_as_a_group(tmp_path: Path) -> None:
    inventory = tmp_path / "inventory.yml"
    inventory.write_text(
        "robots:\n  site_a/r1: {labels: {site: site_a}}\n  site_a/r2: {labels: {site: site_a}}\n",
        encoding="utf-8",
    )
    with in_process_exporter(tmp_path, inventory={"file": str(inventory)}) as running:
        publish(running, "site_a/r1", (2, "/Laser", "no scans"))
        with running_icinga2(tmp_path / "icinga2", SITE_HOST % running.server.url) as daemon:
            result = wait_for(
                lambda: settled_result(daemon, "site_a", "ros-site", 2),
                timeout=60,
                message="the site's result",
            )
    assert result.output.startswith(
        "CRITICAL - 2 robots with site=site_a: site_a/r1 (1 ERROR) (also 1 UNKNOWN)"
    )


def test_icinga2_accepts_the_shipped_definitions_with_no_robots(tmp_path: Path) -> None:
    output = validate(tmp_path, "")
    assert "critical/" not in output


def test_icinga2_check_command_maps_and_describes_every_option(tmp_path: Path) -> None:
    validate(tmp_path, "")
    listing = icinga2(
        tmp_path, "object", "list", "--type", "CheckCommand", "--name", "ros_diagnostics"
    ).stdout
    arguments = dict(re.findall(r"^    \* (--[a-z-]+)\n((?:      \* .*\n)+)", listing, flags=re.MULTILINE))
    options = set(LONG_OPTIONS) - {"--help", "--version"}
    assert set(arguments) == options
    for option, attributes in arguments.items():
        assert "description = " in attributes, option
        assert re.search(r"\$ros_diagnostics_[a-z_]+\$", attributes), option


@pytest.fixture(scope="module")
def icinga(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Icinga2]:
    """Icinga 2 with the shipped definitions, checking robots of a live exporter fed by the simulator."""
    with running_fleet(tmp_path_factory.mktemp("fleet"), fresh_domain_id()) as exporter:
        hosts = robot_hosts(int(exporter.url.rsplit(":", 1)[1]))
        with running_icinga2(tmp_path_factory.mktemp("icinga2"), hosts) as daemon:
            yield daemon


def settled_result(icinga: Icinga2, host: str, service: str, state: int) -> PluginResult | None:
    """Force a check and return the result once it reaches `state`."""
    result = icinga.result(host, service)
    if result is not None and result.state == state:
        return result
    icinga.reschedule(host, service)
    return None


@pytest.mark.parametrize("case", CASES, ids=[case.golden for case in CASES])
def test_icinga2_reports_what_the_check_reports(icinga: Icinga2, case: CheckCase) -> None:
    try:
        result = wait_for(
            lambda: settled_result(icinga, case.robot, case.icinga2_service, case.state),
            timeout=60,
            interval=1.0,
            message=f"{case.robot}!{case.icinga2_service} in state {case.state}",
        )
    except AssertionError as error:
        last = icinga.result(case.robot, case.icinga2_service)
        raise AssertionError(f"{error}\nlast result: {last}\n{icinga.log()}") from None
    assert_matches_golden(case.golden, result)


def test_icinga2_runs_the_subsystem_services_on_their_own_intervals(icinga: Icinga2) -> None:
    intervals = {
        result["name"]: result["attrs"]["check_interval"]
        for result in icinga.api("GET", "/v1/objects/services", {"filter": 'host.name == "robot1"'})[
            "results"
        ]
    }
    assert intervals == {
        "robot1!ros-diagnostics": 60.0,
        "robot1!ros-battery": 60.0,
        "robot1!ros-motor": 300.0,
        "robot1!ros-temperature": 30.0,
    }
