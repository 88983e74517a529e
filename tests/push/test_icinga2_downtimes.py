"""Maintenance windows become downtimes in a real Icinga 2 (Debian's), for each robot's host and services.

Icinga 2 runs with the shipped push ApiUser example (deploy/icinga2/push), whose permissions must cover
scheduling and removing downtimes of the exporter's own hosts only, and with a host an operator made and
put in a downtime by hand. Each test runs an exporter in the test process, its model fed by the test,
pushing to that Icinga 2 with a window API that alice may write; the restart test runs `overseer run` and
the simulator as processes instead, so that it can stop the exporter with SIGTERM and start it again.
"""

from __future__ import annotations

import json
import signal
import time
import urllib.request
from base64 import b64encode
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import bcrypt
import pytest

from overseer.app import Exporter
from testbed.icinga2 import Icinga2, push_api_user, push_config, running_icinga2
from testbed.in_process import call, in_process_exporter, publish
from testbed.nagios import run_check
from testbed.processes import running_exporter, running_simulator, wait_for

pytestmark = pytest.mark.servers

HASH = bcrypt.hashpw(b"secret", bcrypt.gensalt(rounds=4)).decode()
WRITER = {"Authorization": "Basic " + b64encode(b"alice:secret").decode()}
HANDMADE = """object Host "operators-box" {
	check_command = "dummy"
}
"""
COMPONENTS = ((2, "/Power/Battery", "cell failure"), (0, "/Motor/Left", "ok"))


@pytest.fixture(scope="module")
def icinga(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Icinga2]:
    """Icinga 2 with the push ApiUser example and an operator's host in a downtime of the operator's."""
    with running_icinga2(tmp_path_factory.mktemp("icinga2"), push_api_user() + HANDMADE) as daemon:
        now = time.time()
        daemon.api(
            "POST",
            "/v1/actions/schedule-downtime",
            {
                "type": "Host",
                "host": "operators-box",
                "start_time": now,
                "end_time": now + 86400,
                "fixed": True,
                "author": "operator",
                "comment": "the operator's own",
            },
        )
        yield daemon


@contextmanager
def exporter(tmp_path: Path, daemon: Icinga2, exporter_id: str) -> Iterator[Exporter]:
    """An exporter pushing to `daemon` every second, as the example ApiUser; alice may write windows."""
    section = json.loads(push_config(tmp_path, daemon, exporter_id, "1s", timeout="3s").read_text())[
        "icinga2"
    ]
    web_config = tmp_path / "web.yml"
    web_config.write_text(f"basic_auth_users:\n  alice: '{HASH}'\n", encoding="utf-8")
    with in_process_exporter(
        tmp_path,
        web={"config_file": str(web_config), "enable_maintenance_api": True},
        maintenance={"writers": ["alice"]},
        icinga2=section,
    ) as running:
        yield running


def open_window(url: str, robots: str, comment: str) -> dict[str, Any]:
    """Open a three-hour window as alice on the exporter serving at `url`."""
    body = json.dumps({"robots": robots, "duration": "3h", "comment": comment}).encode()
    request = urllib.request.Request(
        url + "/api/v1/maintenance", body, {**WRITER, "Content-Type": "application/json"}, method="POST"
    )
    with urllib.request.urlopen(request, timeout=5) as response:
        assert response.status == 201
        window: dict[str, Any] = json.load(response)["window"]
    return window


def downtimes(daemon: Icinga2) -> dict[str, dict[str, Any]]:
    """Every downtime Icinga holds, by `host!service` (or host): its author, comment, end and entry time."""
    answer = daemon.api(
        "GET",
        "/v1/objects/downtimes",
        {"attrs": ["host_name", "service_name", "author", "comment", "end_time", "entry_time"]},
    )
    return {
        "!".join(filter(None, (item["attrs"]["host_name"], item["attrs"]["service_name"]))): item["attrs"]
        for item in answer["results"]
    }


def objects_of(daemon: Icinga2, host: str) -> set[str]:
    """The host and its services, as `downtimes` names them."""
    names = {name for name in daemon.objects("services") if name.split("!", 1)[0] == host}
    return {host} | names if host in daemon.objects("hosts") else set()


def effects(running: Exporter, name: str) -> dict[str, float]:
    _, body = call(running, "/metrics", headers=WRITER)
    return {
        line.rpartition(" ")[0].removeprefix(name): float(line.rpartition(" ")[2])
        for line in body.decode().splitlines()
        if line.startswith(name + "{") and 'target="icinga2"' in line
    }


def test_a_window_puts_each_robots_host_and_services_in_downtime_until_ended(
    tmp_path: Path, icinga: Icinga2
) -> None:
    with exporter(tmp_path, icinga, "dt1") as running:
        for robot in ("dt1_a/r1", "dt1_a/r2", "dt1_b/r1"):
            publish(running, robot, *COMPONENTS)
        hosts = ("dt1_a.r1", "dt1_a.r2", "dt1_b.r1")
        wait_for(lambda: all(len(objects_of(icinga, h)) == 4 for h in hosts), 30, message="hosts, services")
        window = open_window(running.server.url, "dt1_a/", 'swap <batteries> & "wheels"')
        expected = objects_of(icinga, "dt1_a.r1") | objects_of(icinga, "dt1_a.r2")
        wait_for(lambda: expected <= set(downtimes(icinga)), 15, message="the downtimes")
        held = downtimes(icinga)
        assert {name for name in held if name.startswith("dt1_")} == expected, "dt1_b.r1 is in no window"
        for name in expected:
            assert held[name]["author"] == "alice"
            assert (
                held[name]["comment"]
                == f'swap <batteries> & "wheels" [Overseer maintenance window {window["id"]}]'
            )
            assert abs(held[name]["end_time"] - window["end"]) < 1

        publish(running, "dt1_a/r1", *COMPONENTS, (1, "/Camera/Front", "dirty lens"))  # a new group service
        wait_for(
            lambda: "dt1_a.r1!ros-diagnostics-Camera" in downtimes(icinga),
            15,
            message="the new service's downtime",
        )
        output = wait_for(
            lambda: (r := icinga.host_result("dt1_a.r1")) and "maintenance" in r.output and r,
            15,
            message="output",
        ).output
        assert (
            f"[in maintenance until {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime(window['end']))}"
            in output
        )
        checked = run_check("--url", running.server.url, "-r", "dt1_a/r2", "-a", "alice:secret")
        assert checked.state == 2, "a window leaves the check's state as it is"
        assert "[in maintenance until" in checked.output and 'swap <batteries> & "wheels"]' in checked.output

        status, _ = call(running, f"/api/v1/maintenance/{window['id']}", "DELETE", None, WRITER)
        assert status == 200
        wait_for(
            lambda: not any(name.startswith("dt1_") for name in downtimes(icinga)),
            15,
            message="downtimes removed",
        )
        assert "operators-box" in downtimes(icinga), "the operator's own downtime was touched"
        counts = effects(running, "overseer_maintenance_effects_total")
    assert counts['{action="created",target="icinga2"}'] == 3  # two hosts, then the new service
    assert counts['{action="removed",target="icinga2"}'] == 2


def test_an_icinga_that_was_down_gets_the_downtime_once_back(tmp_path: Path) -> None:
    with (
        running_icinga2(tmp_path / "icinga2", push_api_user()) as daemon,
        exporter(tmp_path, daemon, "dt2") as running,
    ):
        publish(running, "dt2/r1", *COMPONENTS)
        wait_for(lambda: len(objects_of(daemon, "dt2.r1")) == 4, 30, message="host and services")
        daemon.stop()
        window = open_window(running.server.url, "dt2/r1", "motor swap")
        wait_for(
            lambda: effects(running, "overseer_maintenance_effects_pending") == {'{target="icinga2"}': 1.0},
            15,
            message="the downtime pending",
        )
        daemon.start()
        wait_for(lambda: len(downtimes(daemon)) == 4, 60, message="the downtime once Icinga is back")
        assert all(window["id"] in item["comment"] for item in downtimes(daemon).values())
        wait_for(
            lambda: effects(running, "overseer_maintenance_effects_pending") == {'{target="icinga2"}': 0.0},
            15,
            message="nothing pending",
        )


def test_a_robot_first_seen_in_a_window_is_in_downtime_before_its_first_result(
    tmp_path: Path, icinga: Icinga2
) -> None:
    with exporter(tmp_path, icinga, "dt4") as running:
        open_window(running.server.url, "dt4/", "new robots arrive parked")
        publish(running, "dt4/r1", *COMPONENTS)
        wait_for(lambda: len(objects_of(icinga, "dt4.r1")) == 4, 30, message="host and services")
        wait_for(lambda: objects_of(icinga, "dt4.r1") <= set(downtimes(icinga)), 15, message="downtimes")
        entered = {name: held["entry_time"] for name, held in downtimes(icinga).items()}
        services = icinga.api(
            "GET", "/v1/objects/services", {"attrs": ["host_name", "state", "last_hard_state_change"]}
        )["results"]
    problems = {
        item["name"]: item["attrs"]["last_hard_state_change"]
        for item in services
        if item["attrs"]["host_name"] == "dt4.r1" and item["attrs"]["state"] != 0
    }
    assert len(problems) == 2  # ros-diagnostics and ros-diagnostics-Power are CRITICAL from the start
    late = {
        name: round(entered[name] - changed, 3)
        for name, changed in problems.items()
        if entered[name] > changed
    }
    assert not late, f"downtimes entered after the first result (seconds late): {late}"


WATCH_SECONDS = 20.0  # after a restart: longer than the downtimes' resync (10 s) and a result's TTL (2 s)


def process_config(tmp_path: Path, daemon: Icinga2, exporter_id: str) -> Path:
    """An `overseer run` --config.file: the push every second (results live 2 s), alice may write windows.

    Its database (the windows, and the downtimes made for them) is in `tmp_path`, for every run.
    """
    section = json.loads(push_config(tmp_path, daemon, exporter_id, "1s", timeout="3s").read_text())[
        "icinga2"
    ]
    web_config = tmp_path / "web.yml"
    web_config.write_text(f"basic_auth_users:\n  alice: '{HASH}'\n", encoding="utf-8")
    config = {
        "web": {"config_file": str(web_config), "enable_maintenance_api": True},
        "maintenance": {"writers": ["alice"]},
        "icinga2": section,
        "events": {"path": str(tmp_path / "events.db")},
    }
    path = tmp_path / "overseer.yml"
    path.write_text(json.dumps(config), encoding="utf-8")
    return path


def downtime_names(daemon: Icinga2, hosts: tuple[str, ...]) -> set[str]:
    """The names of the downtimes Icinga holds for `hosts` and their services."""
    answer = daemon.api("GET", "/v1/objects/downtimes", {"attrs": ["host_name"]})
    return {item["name"] for item in answer["results"] if item["attrs"]["host_name"] in hosts}


def states(daemon: Icinga2, hosts: tuple[str, ...]) -> dict[str, tuple[int, int, float]]:
    """`hosts` and their services (as `downtimes` names them): (state, downtime_depth, last_check)."""
    found: dict[str, tuple[int, int, float]] = {}
    for kind in ("hosts", "services"):
        answer = daemon.api(
            "GET", f"/v1/objects/{kind}", {"attrs": ["state", "downtime_depth", "last_check"]}
        )
        for item in answer["results"]:
            if item["name"].split("!", 1)[0] in hosts:
                attrs = item["attrs"]
                found[item["name"]] = (int(attrs["state"]), int(attrs["downtime_depth"]), attrs["last_check"])
    return found


def test_a_restart_keeps_the_downtimes_of_robots_in_maintenance_switched_off_or_not(
    tmp_path: Path, icinga: Icinga2, dds_domain: int
) -> None:
    config = process_config(tmp_path, icinga, "dt3")
    run = (f"--config.file={config}", "--fleet.stale-after=1s", "--fleet.robot-timeout=2s")
    off, on = "dt3_off.r1", "dt3_on.r1"
    hosts = (off, on)
    polls: list[tuple[float, dict[str, tuple[int, int, float]], set[str]]] = []

    def poll() -> None:
        polls.append((time.monotonic() - stopping, states(icinga, hosts), downtime_names(icinga, hosts)))
        time.sleep(0.2)

    with running_simulator(
        tmp_path, dds_domain, "--robots=1", "--namespace-prefix=dt3_on/r", "--rate=5"
    ) as publishing:
        with running_exporter(tmp_path, dds_domain, *run) as first:
            with running_simulator(
                tmp_path, dds_domain, "--robots=1", "--namespace-prefix=dt3_off/r", "--rate=5"
            ):
                wait_for(lambda: all(len(objects_of(icinga, h)) == 7 for h in hosts), 60, message="objects")
                open_window(first.url, "dt3_off/r1", "switched off for a repair")
                open_window(first.url, "dt3_on/", "calibration")
                wait_for(
                    lambda: all(depth > 0 for _, depth, _ in states(icinga, hosts).values()),
                    15,
                    message="both robots in downtime",
                )
            # Its publisher gone, dt3_off/r1 is down, and Icinga says so inside its downtime.
            wait_for(lambda: states(icinga, hosts)[off][0] == 1, 30, message=f"{off} DOWN")
            before = downtime_names(icinga, hosts)
            objects = set(states(icinga, hosts))
            judged = states(icinga, hosts)[off][2]
            # Watched from the SIGTERM on: the old exporter's last results live 2 s, so the switched-off
            # robot's run out while it stops or the new one starts, and Icinga's own check says DOWN.
            stopping = time.monotonic()
            first.process.send_signal(signal.SIGTERM)
            while first.process.poll() is None:
                poll()
        # dt3_on/r1 pauses until the new exporter has found its hosts (and synced the downtimes), as a
        # fleet whose discovery takes a while: its first sync comes before it hears either robot.
        publishing.process.send_signal(signal.SIGSTOP)
        started, started_wall = time.monotonic() - stopping, time.time()
        try:
            with running_exporter(tmp_path, dds_domain, *run) as second:
                while "hosts of this exporter" not in second.log() and time.monotonic() - stopping < 60:
                    poll()
                poll()
                publishing.process.send_signal(signal.SIGCONT)
                watched = time.monotonic() + WATCH_SECONDS
                while time.monotonic() < watched:
                    poll()
                log = second.log()
        finally:
            publishing.process.send_signal(signal.SIGCONT)  # also when the new exporter did not start
    assert len(before) == len(objects) == 14, before  # per robot: its host and 6 services
    assert "found 2 hosts of this exporter (dt3)" in log
    after = f"{polls[-1][0]:.1f} s after the SIGTERM (the new exporter started at {started:.1f} s)"
    assert all(set(seen) == objects for _, seen, _ in polls), "an object vanished"
    outside = {
        host: [
            at
            for at, seen, _ in polls
            if any(not depth for n, (_, depth, _) in seen.items() if n.split("!")[0] == host)
        ]
        for host in hosts
    }
    assert not any(outside.values()), "; ".join(
        f"{host} or a service of it out of downtime at {len(ats)} of {len(polls)} polls over {after}"
        + (f", from {ats[0]:.1f} s to {ats[-1]:.1f} s" if ats else "")
        for host, ats in outside.items()
    )
    remade = [(at, sorted(names ^ before)) for at, _, names in polls if names != before]
    assert not remade, (
        f"downtimes removed or made again at {len(remade)} of {len(polls)} polls over {after}, first at "
        f"{remade[0][0]:.1f} s: {remade[0][1]}"
    )
    not_down = [at for at, seen, _ in polls if seen[off][0] != 1]
    assert not not_down, f"{off} was not DOWN at {len(not_down)} polls, first at {not_down[0]:.1f} s"
    last = polls[-1][1]
    assert last[off][2] > judged, f"Icinga did not judge {off} again (its TTL ran out, or a DOWN came)"
    assert last[on][2] > started_wall, f"no result for {on} from the new exporter"
