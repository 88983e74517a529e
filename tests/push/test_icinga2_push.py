"""Push mode: the exporter registers robots in a real Icinga 2 and pushes their results over its REST API.

One Icinga 2 daemon for the module, with the shipped push ApiUser example (deploy/icinga2/push) as the
only user the exporters log in as, and objects an operator made by hand. Each test runs its own
exporter, with an exporter id and robot names of its own, fed by the simulator over DDS.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from overseer.config import ConfigError
from overseer.config.icinga2 import icinga2_config
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.push import icinga2_push
from overseer.push.icinga2_client import Icinga2Client, object_path
from overseer.push.icinga2_names import group_pattern, host_name, original_name, robot_name
from overseer.push.icinga2_objects import HOST_SILENT_TEXT
from overseer.push.icinga2_push import Icinga2Push
from support.push_fleet import FleetFailingOnce
from testbed.icinga2 import (
    PUSH_CERT_USER,
    Icinga2,
    client_certificate,
    push_api_user,
    push_cert_api_user,
    push_config,
    running_icinga2,
)
from testbed.nagios import PluginResult, run_check
from testbed.ports import fresh_domain_id
from testbed.processes import Exporter, overseer_command, running_exporter, running_simulator, wait_for

HANDMADE = """object Host "handmade" {
	check_command = "dummy"
	vars.ros_robot = "handmade"
}
object Service "keep-me" {
	host_name = "handmade"
	check_command = "dummy"
}
object Host "taken1" {
	check_command = "dummy"
	vars.owner = "operator"
}
template Host "fleet-robot" {
	vars.site_contact = "robots@example"
}
template Service "fleet-diagnostics" {
	vars.notes_from_template = "pushed by overseer"
}
"""
FAST_FLEET = ("--fleet.stale-after=1s", "--fleet.robot-timeout=2s")
GROUP_SERVICES = {f"ros-diagnostics-{group}" for group in ("Power", "Motor", "Temp", "Laser", "Camera")}


@pytest.fixture(scope="module")
def icinga(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Icinga2]:
    """Icinga 2 with the push ApiUser example (by password, and by certificate) and hand-made objects."""
    objects = push_api_user() + push_cert_api_user() + HANDMADE
    with running_icinga2(tmp_path_factory.mktemp("icinga2"), objects) as daemon:
        yield daemon


def services_of(icinga: Icinga2, host: str) -> dict[str, dict[str, object]]:
    """The services of `host` by short name, with their vars."""
    return {
        name.split("!", 1)[1]: variables
        for name, variables in icinga.objects("services").items()
        if name.split("!", 1)[0] == host
    }


def pushed(icinga: Icinga2, host: str, service: str) -> PluginResult | None:
    """The service's last result, None while the host or service does not exist yet."""
    if host not in icinga.objects("hosts") or service not in services_of(icinga, host):
        return None
    return icinga.result(host, service)


def checked(exporter: Exporter, robot: str, *args: str) -> PluginResult:
    """What the real check_ros_diagnostics prints for `robot` against the same exporter."""
    result = run_check("--url", exporter.url, "-r", robot, *args)
    return PluginResult(result.state, result.output.rstrip("\n"))


def push_metric(exporter: Exporter, result: str) -> float:
    """overseer_icinga2_pushes_total for one result label (0 when absent)."""
    samples = exporter.samples().get("overseer_icinga2_pushes_total", {})
    return samples.get((("result", result),), 0.0)


def test_names_map_robots_to_icinga_objects_reversibly() -> None:
    for robot in ("robot1", "site_a/robot7", "odd.name~x", "with space/ü!"):
        host = host_name(robot)
        assert re.fullmatch(r"[A-Za-z0-9_.~-]+", host), host
        assert robot_name(host) == robot
    assert host_name("site_a/robot7") == "site_a.robot7"
    assert original_name("Motor~20Drivers") == "Motor Drivers"
    assert re.search(group_pattern("Power"), "/Power/Robot Battery")
    assert re.search(group_pattern("Power"), "/Power")
    assert not re.search(group_pattern("Power"), "/PowerSupply/x")


@pytest.mark.servers
@pytest.mark.parametrize(
    ("changes", "message"),
    [
        (
            {"username": None, "password_file": None},
            "icinga2: give username and password_file, or client_cert",
        ),
        ({"password_file": None}, "icinga2.password_file: required with icinga2.username"),
        ({"client_key": "k.pem"}, "icinga2.client_cert: required with icinga2.client_key"),
        (
            {"services": ["robot", "everything"]},
            "icinga2.services: expected robot or groups, got 'everything'",
        ),
        ({"url": None}, "icinga2.url: expected a non-empty string, got None"),
    ],
)
def test_an_incomplete_icinga2_section_names_the_key(
    icinga: Icinga2, tmp_path: Path, changes: dict[str, object], message: str
) -> None:
    password = tmp_path / "pw"
    password.write_text("secret\n", encoding="utf-8")
    section: dict[str, object] = {
        "url": "https://127.0.0.1:5665",
        "username": "u",
        "password_file": str(password),
        "ca_file": str(icinga.ca_file),
        **changes,
    }
    with pytest.raises(ConfigError) as raised:
        icinga2_config({key: value for key, value in section.items() if value is not None})
    assert str(raised.value).startswith(message), raised.value


@pytest.mark.servers
def test_results_sent_in_one_write_get_their_own_answers_in_order(icinga: Icinga2, tmp_path: Path) -> None:
    section = json.loads(push_config(tmp_path, icinga, "piped", "1h").read_text())["icinga2"]
    client = Icinga2Client(icinga2_config(section))
    marks = {"check_command": "dummy", "vars.overseer_managed": True, "enable_active_checks": False}
    for host in ("piped.a", "piped.b"):
        client.expect("PUT", object_path("hosts", host), {"attrs": marks})

    def result(host: str, state: int) -> dict[str, object]:
        return {"type": "Host", "host": host, "exit_status": state, "plugin_output": f"{host} {state}"}

    bodies = [result("piped.a", 1), result("piped.none", 0), result("piped.b", 0), result("piped.a", 0)]
    try:
        answers, error = client.pipeline("/v1/actions/process-check-result", bodies)
        assert error is None
        assert [status for status, _ in answers] == [200, 404, 200, 200]
        assert "piped.b" in answers[2][1]["results"][0]["status"]  # each answer is its own request's
        host = icinga.api("GET", "/v1/objects/hosts", {"host": "piped.a"})["results"][0]["attrs"]
        assert host["last_check_result"]["output"] == "piped.a 0"  # the last one sent for it
        again, error = client.pipeline("/v1/actions/process-check-result", [result("piped.b", 1)])
        assert (error, [status for status, _ in again]) == (None, [200])  # the same connection goes on
        # The kept-alive connection broken under it (as Icinga's close of an idle one can be met under
        # load, a TLS error while the batch is written): sent again once, on a new connection.
        kept = client._connection
        assert kept is not None and kept.sock is not None
        socket.socket.shutdown(kept.sock, socket.SHUT_RDWR)
        again, error = client.pipeline("/v1/actions/process-check-result", [result("piped.b", 0)] * 50)
        assert (error, {status for status, _ in again}, len(again)) == (None, {200}, 50)
    finally:
        client.close()


@pytest.mark.servers
def test_a_request_on_a_connection_broken_under_it_is_sent_again_on_a_new_one(
    icinga: Icinga2, tmp_path: Path
) -> None:
    section = json.loads(push_config(tmp_path, icinga, "resent", "1h").read_text())["icinga2"]
    client = Icinga2Client(icinga2_config(section))
    try:
        assert client.expect("GET", "/v1/objects/hosts", {"attrs": ["name"]})["results"] is not None
        kept = client._connection
        assert kept is not None and kept.sock is not None
        # Gone as the old process's connections go when Icinga reloads to run a stage: writing the next
        # request on it is a TLS error, not an answer missing.
        socket.socket.shutdown(kept.sock, socket.SHUT_RDWR)
        status, document = client.request("GET", "/v1/objects/hosts", {"attrs": ["name"]})
        assert status == 200 and isinstance(document["results"], list)
        assert client._connection is not None and client._connection is not kept
    finally:
        client.close()


class RecordedTicks(threading.Event):
    """The push's stop event, recording how long each tick waits; set at the first wait of a whole tick."""

    def __init__(self) -> None:
        """Nothing waited yet."""
        super().__init__()
        self.waits: list[float | None] = []

    def wait(self, timeout: float | None = None) -> bool:
        """Note `timeout`; stop the push at a tick's full wait (nothing left to deliver), or after many."""
        self.waits.append(timeout)
        if timeout or len(self.waits) > 1000:
            self.set()
        return self.is_set()


@pytest.mark.servers
def test_a_push_with_results_still_waiting_delivers_again_without_waiting_a_tick(
    icinga: Icinga2, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An in-process push into the real Icinga 2, one result a tick: it waits only once nothing is left."""
    monkeypatch.setattr(icinga2_push, "BATCH_SECONDS", 0.0)  # delivering stops after each result
    section = json.loads(push_config(tmp_path, icinga, "ticks", "1h").read_text())["icinga2"]
    model = FleetModel(FleetLimits(stale_after=600, robot_timeout=1200))
    robots = [f"ticks/robot{index}" for index in range(5)]
    for robot in robots:
        model.apply(
            robot, DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/Power/Battery", "ok", "", ()),)), "dds"
        )
    push = Icinga2Push(icinga2_config(section), FleetFailingOnce(model, 0), 3600.0)  # type: ignore[arg-type]
    ticks = RecordedTicks()
    push._stopping = ticks
    try:
        push._run()
    finally:
        push._client.close()
    # A host, robot and Power result a robot: 15 deliveries, each followed at once by the next.
    assert ticks.waits == [0] * 14 + [icinga2_push.TICK_SECONDS]
    pushed = icinga.api("GET", "/v1/objects/hosts", {"attrs": ["name", "last_check_result"]})["results"]
    assert sorted(host["name"] for host in pushed if host["name"].startswith("ticks.")) == [
        host_name(robot) for robot in robots
    ]
    assert all(host["attrs"]["last_check_result"] for host in pushed if host["name"].startswith("ticks."))


@pytest.mark.servers
def test_robots_register_themselves_and_push_what_the_check_prints(icinga: Icinga2, tmp_path: Path) -> None:
    domain = fresh_domain_id()
    config = push_config(tmp_path, icinga, "same-output", "1h")
    with (
        running_exporter(tmp_path, domain, f"--config.file={config}") as exporter,
        running_simulator(tmp_path, domain, "--robots=2", "--namespace-prefix=site_a/arobot", "--rate=2"),
    ):
        host = "site_a.arobot1"
        wait_for(lambda: pushed(icinga, host, "ros-diagnostics"), timeout=60, message="the robot's host")
        assert icinga.objects("hosts")[host] == {
            "ros_robot": "site_a/arobot1",
            "overseer_managed": True,
            "overseer_exporter": "same-output",
            "dummy_state": 3,
            "dummy_text": HOST_SILENT_TEXT,
        }
        wait_for(
            lambda: set(services_of(icinga, host)) == {"ros-diagnostics", *GROUP_SERVICES},
            timeout=30,
            message="the group services",
        )
        wait_for(lambda: "site_a.arobot2" in icinga.objects("hosts"), timeout=30, message="the second robot")
        expected = {"ros-diagnostics": checked(exporter, "site_a/arobot1")}
        for service in GROUP_SERVICES:
            group = service.removeprefix("ros-diagnostics-")
            expected[service] = checked(exporter, "site_a/arobot1", f"--name-regex={group_pattern(group)}")
        assert expected["ros-diagnostics"].state == 2  # the simulator's default: one ERROR, one WARN
        for service, result in expected.items():
            try:
                wait_for(
                    lambda s=service, r=result: pushed(icinga, host, s) == r, timeout=15, message=service
                )
            except AssertionError as error:
                raise AssertionError(
                    f"{error}\ncheck: {result}\npushed: {pushed(icinga, host, service)}"
                ) from None
        host_result = icinga.host_result(host)
        assert host_result == PluginResult(0, "UP - site_a/arobot1: diagnostics arriving")
        assert push_metric(exporter, "ok") > 0
        assert exporter.samples()["overseer_icinga2_pending_results"][()] == 0


@pytest.mark.servers
def test_a_client_certificate_authenticates_instead_of_a_password(icinga: Icinga2, tmp_path: Path) -> None:
    domain = fresh_domain_id()
    certificate = client_certificate(icinga.root, PUSH_CERT_USER)
    config = push_config(tmp_path, icinga, "by-cert", "1h", client_cert=certificate)
    assert "password" not in config.read_text(encoding="utf-8")
    with (
        running_exporter(tmp_path, domain, f"--config.file={config}") as exporter,
        running_simulator(tmp_path, domain, "--robots=1", "--namespace-prefix=grobot", "--rate=2"),
    ):
        wait_for(lambda: pushed(icinga, "grobot1", "ros-diagnostics"), timeout=60, message="the robot's host")
        assert icinga.objects("hosts")["grobot1"]["overseer_exporter"] == "by-cert"
        created_by = wait_for(  # Icinga writes its log in its own time
            lambda: re.search(
                r"Request: PUT /v1/objects/hosts/grobot1 \(from [^)]*\), user: ([^,]+),", icinga.log()
            ),
            timeout=30,
            message="the creation in Icinga's log",
        )
        assert created_by is not None and created_by.group(1) == PUSH_CERT_USER
        assert push_metric(exporter, "ok") > 0


@pytest.mark.servers
def test_the_icinga2_flags_override_the_file_and_name_their_key(tmp_path: Path) -> None:
    done = subprocess.run(
        [
            *overseer_command(),
            "run",
            "--icinga2.url=https://127.0.0.1:5665",
            "--icinga2.username=u",
            "--icinga2.password-file=/nonexistent/pw",
            "--icinga2.ca-file=/etc/ssl/certs/ca-certificates.crt",
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert done.returncode == 2
    assert done.stderr == (
        "overseer run: configuration error: --icinga2.password-file (icinga2.password_file): "
        "cannot read '/nonexistent/pw': No such file or directory\n"
    )


@pytest.mark.servers
def test_a_group_that_vanished_is_judged_as_the_check_judges_it(icinga: Icinga2, tmp_path: Path) -> None:
    domain = fresh_domain_id()
    config = push_config(tmp_path, icinga, "vanished", "1h")
    with (
        running_exporter(
            tmp_path, domain, f"--config.file={config}", *FAST_FLEET, "--fleet.expire-after=4s"
        ) as exporter,
        running_simulator(
            tmp_path,
            domain,
            "--robots=1",
            "--namespace-prefix=irobot",
            "--rate=5",
            "--event=8:irobot1:/Camera/Cam1:silence",
            "--event=8:irobot1:/Camera/Cam2:silence",
        ),
    ):
        wait_for(
            lambda: pushed(icinga, "irobot1", "ros-diagnostics-Camera"), timeout=60, message="the service"
        )

        def camera_forgotten() -> bool:
            robot = exporter.robot("irobot1")
            return robot is not None and not any(c["name"].startswith("/Camera") for c in robot["components"])

        wait_for(camera_forgotten, timeout=60, message="the Camera components forgotten")
        expected = checked(exporter, "irobot1", f"--name-regex={group_pattern('Camera')}")
        assert expected.state == 3 and "no component with name matching" in expected.output
        wait_for(
            lambda: pushed(icinga, "irobot1", "ros-diagnostics-Camera") == expected,
            timeout=10,
            message="the check's verdict on the vanished group",
        )


@pytest.mark.servers
@pytest.mark.parametrize("workers", [1, 2])
def test_a_level_change_arrives_at_once(icinga: Icinga2, tmp_path: Path, workers: int) -> None:
    # With ingest workers the push reads their robots' digests and fetches only the robots it pushes.
    domain = fresh_domain_id()
    robot = f"w{workers}robot1"
    config = push_config(tmp_path, icinga, f"at-once-{workers}", "1h")  # the periodic push is an hour away
    options = (f"--config.file={config}", f"--ingest.workers={workers}")
    with (
        running_exporter(tmp_path, domain, *options) as exporter,
        running_simulator(
            tmp_path,
            domain,
            "--robots=1",
            f"--namespace-prefix=w{workers}robot",
            "--warn=0",
            "--error=0",
            "--rate=5",
            f"--event=12:{robot}:/Power/Robot Battery:ERROR",
        ),
    ):
        wait_for(
            lambda: (result := pushed(icinga, robot, "ros-diagnostics-Power")) and result.state == 0,
            timeout=60,
            message="Power OK in Icinga",
        )

        def exporter_sees_error() -> bool:
            document = exporter.robot(robot)
            return document is not None and document["counts"]["error"] > 0

        wait_for(exporter_sees_error, timeout=30, interval=0.05, message="the ERROR in the exporter")
        seen = time.monotonic()
        wait_for(
            lambda: icinga.result(robot, "ros-diagnostics-Power").state == 2,  # type: ignore[union-attr]
            timeout=2,
            interval=0.05,
            message="the ERROR in Icinga within 2 s",
        )
        assert time.monotonic() - seen < 2
        assert icinga.result(robot, "ros-diagnostics") == checked(exporter, robot)


@pytest.mark.servers
def test_icinga_down_then_back_gets_the_latest_state(icinga: Icinga2, tmp_path: Path) -> None:
    domain = fresh_domain_id()
    config = push_config(tmp_path, icinga, "outage", "1h")
    with running_exporter(tmp_path, domain, f"--config.file={config}", *FAST_FLEET) as exporter:
        with running_simulator(tmp_path, domain, "--robots=1", "--namespace-prefix=crobot", "--rate=5"):
            wait_for(lambda: pushed(icinga, "crobot1", "ros-diagnostics"), timeout=60, message="the host")
            wait_for(
                lambda: (
                    icinga.host_result("crobot1") == PluginResult(0, "UP - crobot1: diagnostics arriving")
                ),
                timeout=30,
                message="the robot UP in Icinga",
            )
            icinga.stop()
        try:  # the robot goes down while Icinga is away; the exporter keeps serving and keeps trying
            wait_for(lambda: not exporter.robot("crobot1")["up"], timeout=30, message="robot down")  # type: ignore[index]
            wait_for(lambda: push_metric(exporter, "connection") >= 2, timeout=30, message="failed pushes")
            assert exporter.samples()["overseer_icinga2_pending_results"][()] == 7  # host + 6 services
        finally:
            icinga.start()
        wait_for(
            lambda: icinga.host_result("crobot1").state == 1,  # type: ignore[union-attr]
            timeout=60,
            message="the robot DOWN in Icinga",
        )
        expected = checked(exporter, "crobot1")
        assert expected.state == 3 and "crobot1 is down" in expected.output
        result = icinga.result("crobot1", "ros-diagnostics")
        assert (
            result is not None
            and result.state == 3
            and result.output.startswith("UNKNOWN - crobot1 is down:")
        )
        wait_for(
            lambda: exporter.samples()["overseer_icinga2_pending_results"][()] == 0,
            timeout=30,
            message="nothing pending",
        )
        assert "Icinga 2 push failed" in exporter.log() and "accepts results again" in exporter.log()


@pytest.mark.servers
def test_a_frozen_icinga_times_out_and_then_gets_the_latest_state(icinga: Icinga2, tmp_path: Path) -> None:
    domain = fresh_domain_id()
    config = push_config(tmp_path, icinga, "frozen", "1h", timeout="1s")
    with running_exporter(tmp_path, domain, f"--config.file={config}", *FAST_FLEET) as exporter:
        with running_simulator(tmp_path, domain, "--robots=1", "--namespace-prefix=hrobot", "--rate=5"):
            wait_for(
                lambda: (
                    icinga.host_result("hrobot1") == PluginResult(0, "UP - hrobot1: diagnostics arriving")
                ),
                timeout=60,
                message="the robot UP in Icinga",
            )
            os.killpg(icinga.process.pid, signal.SIGSTOP)  # Icinga accepts connections but never answers
        try:
            wait_for(lambda: push_metric(exporter, "timeout") >= 1, timeout=30, message="a timed-out push")
            # The push in flight at the freeze may time out before robot_timeout has passed.
            wait_for(lambda: not exporter.robot("hrobot1")["up"], timeout=10, message="the robot down")  # type: ignore[index]
        finally:
            os.killpg(icinga.process.pid, signal.SIGCONT)
        wait_for(
            lambda: icinga.host_result("hrobot1").state == 1,  # type: ignore[union-attr]
            timeout=60,
            message="the robot DOWN in Icinga",
        )
        assert "no answer from https://127.0.0.1" in exporter.log()


@pytest.mark.servers
def test_a_restarted_exporter_reuses_its_objects(icinga: Icinga2, tmp_path: Path) -> None:
    domain = fresh_domain_id()
    config = push_config(tmp_path, icinga, "restart", "1h")
    with running_simulator(tmp_path, domain, "--robots=2", "--namespace-prefix=drobot", "--rate=2"):
        for _ in range(2):
            with running_exporter(tmp_path, domain, f"--config.file={config}") as exporter:
                wait_for(
                    lambda e=exporter: push_metric(e, "ok") >= 14, timeout=60, message="2 hosts, 12 services"
                )
                assert [key for key in exporter.samples()["overseer_icinga2_pushes_total"]] == [
                    (("result", "ok"),)
                ]
                assert "WARNING" not in exporter.log() and "ERROR" not in exporter.log()
    hosts = [name for name in icinga.objects("hosts") if name.startswith("drobot")]
    assert sorted(hosts) == ["drobot1", "drobot2"]
    assert len(services_of(icinga, "drobot1")) == 6
    assert "found 2 hosts of this exporter" in exporter.log()


@pytest.mark.servers
def test_a_killed_exporter_turns_its_services_unknown_by_ttl(icinga: Icinga2, tmp_path: Path) -> None:
    domain = fresh_domain_id()
    config = push_config(tmp_path, icinga, "killed", "2s")  # results live 4 s
    with running_simulator(
        tmp_path, domain, "--robots=1", "--namespace-prefix=erobot", "--warn=0", "--error=0"
    ):
        with running_exporter(tmp_path, domain, f"--config.file={config}") as exporter:
            wait_for(
                lambda: (result := pushed(icinga, "erobot1", "ros-diagnostics")) and result.state == 0,
                timeout=60,
                message="the robot OK in Icinga",
            )
            exporter.stop(signal.SIGKILL)
            killed = time.monotonic()
        silent = wait_for(
            lambda: (result := icinga.result("erobot1", "ros-diagnostics")) and result.state == 3 and result,
            timeout=30,
            message="UNKNOWN by TTL",
        )
    assert time.monotonic() - killed >= 2  # not before the TTL ran out (4 s after the last push)
    assert (
        silent.output
        == "UNKNOWN - no result from the Overseer exporter within its TTL: the exporter is silent"
    )
    wait_for(lambda: icinga.host_result("erobot1").state == 1, timeout=30, message="host DOWN")  # type: ignore[union-attr]
    assert "exporter is silent" in icinga.host_result("erobot1").output  # type: ignore[union-attr]


@pytest.mark.servers
def test_a_wrong_password_is_logged_and_counted_and_the_exporter_keeps_serving(
    icinga: Icinga2, tmp_path: Path
) -> None:
    domain = fresh_domain_id()
    config = push_config(tmp_path, icinga, "wrong", "1h", password="not-the-password")
    with (
        running_exporter(tmp_path, domain, f"--config.file={config}") as exporter,
        running_simulator(tmp_path, domain, "--robots=1", "--namespace-prefix=frobot"),
    ):
        wait_for(lambda: exporter.robot("frobot1"), timeout=30, message="the robot in the exporter")
        wait_for(lambda: push_metric(exporter, "http_401") >= 2, timeout=30, message="refused pushes")
        assert exporter.process.poll() is None
        assert "refused the credentials (HTTP 401): check icinga2.username and icinga2.password_file" in (
            exporter.log()
        )
        assert "not-the-password" not in exporter.log()
        assert push_metric(exporter, "ok") == 0
    assert "frobot1" not in icinga.objects("hosts")


@pytest.mark.servers
def test_a_forgotten_robot_is_deleted_and_handmade_objects_are_untouched(
    icinga: Icinga2, tmp_path: Path
) -> None:
    domain = fresh_domain_id()
    config = push_config(tmp_path, icinga, "expiry", "1h")
    before = {name: icinga.objects("hosts")[name] for name in ("handmade", "taken1")}
    services_before = {name: services_of(icinga, name) for name in ("handmade", "taken1")}
    assert "keep-me" in services_before["handmade"]
    with running_exporter(
        tmp_path, domain, f"--config.file={config}", *FAST_FLEET, "--fleet.expire-after=4s"
    ) as exporter:
        with running_simulator(tmp_path, domain, "--robots=2", "--namespace-prefix=taken", "--rate=5"):
            wait_for(lambda: pushed(icinga, "taken2", "ros-diagnostics"), timeout=60, message="taken2's host")
            wait_for(
                lambda: "host taken1 exists and was not made by this exporter" in exporter.log(), timeout=10
            )
        wait_for(lambda: "taken2" not in icinga.objects("hosts"), timeout=30, message="taken2 deleted")
        assert not services_of(icinga, "taken2")
        assert "robot taken2 was forgotten" in exporter.log()
    hosts = icinga.objects("hosts")
    assert {name: hosts[name] for name in ("handmade", "taken1")} == before
    assert {name: services_of(icinga, name) for name in ("handmade", "taken1")} == services_before


@pytest.mark.servers
@pytest.mark.parametrize(
    ("section", "message"),
    [
        ("  colour: blue\n", "icinga2.colour: unknown key"),
        ("  ca_file: /nonexistent/ca.crt\n", "icinga2.ca_file: cannot read '/nonexistent/ca.crt'"),
        ("  password_file: /nonexistent/pw\n", "icinga2.password_file: cannot read '/nonexistent/pw'"),
        ("  interval: soon\n", "icinga2.interval: expected a duration such as 5s, got 'soon'"),
        ("  url: http://icinga:5665\n", "icinga2.url: expected https://HOST:PORT"),
    ],
)
def test_a_bad_icinga2_section_stops_the_exporter_naming_the_key(
    icinga: Icinga2, tmp_path: Path, section: str, message: str
) -> None:
    password = tmp_path / "pw"
    password.write_text("secret\n", encoding="utf-8")
    base = {
        "url": "https://127.0.0.1:5665",
        "username": "u",
        "password_file": str(password),
        "ca_file": str(icinga.ca_file),
    }
    key = section.split(":", 1)[0].strip()
    lines = "".join(f"  {name}: {value}\n" for name, value in base.items() if name != key)
    config = tmp_path / "bad.yml"
    config.write_text("icinga2:\n" + lines + section, encoding="utf-8")
    done = subprocess.run(
        [*overseer_command(), "run", f"--config.file={config}"], capture_output=True, text=True, timeout=30
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith("overseer run: configuration error: " + message), done.stderr
    assert "secret" not in done.stderr


@pytest.mark.servers
def test_pushed_objects_import_the_configured_templates(icinga: Icinga2, tmp_path: Path) -> None:
    domain = fresh_domain_id()
    config = push_config(tmp_path, icinga, "templates", "1h")
    section = json.loads(config.read_text(encoding="utf-8"))
    section["icinga2"].update(host_template="fleet-robot", service_template="fleet-diagnostics")
    config.write_text(json.dumps(section), encoding="utf-8")
    with (
        running_exporter(tmp_path, domain, f"--config.file={config}"),
        running_simulator(tmp_path, domain, "--robots=1", "--namespace-prefix=tmpl"),
    ):
        wait_for(lambda: pushed(icinga, "tmpl1", "ros-diagnostics"), timeout=60, message="the robot's host")
        assert icinga.objects("hosts")["tmpl1"]["site_contact"] == "robots@example"
        assert icinga.objects("hosts")["tmpl1"]["overseer_exporter"] == "templates"
        service_vars = services_of(icinga, "tmpl1")["ros-diagnostics"]
        assert service_vars["notes_from_template"] == "pushed by overseer"
