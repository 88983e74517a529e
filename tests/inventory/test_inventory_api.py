"""The inventory through a whole exporter in the test process: metrics, API, reload, retire, the check.

The exporter has no transport: the tests publish into its model by hand (`testbed.in_process`), and read
it as Prometheus, the check, `overseer robots` and an operator's curl would.
"""

from __future__ import annotations

import base64
import json
import subprocess
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import bcrypt
from prometheus_client.parser import text_string_to_metric_families

from overseer.app import Exporter
from testbed.in_process import call, in_process_exporter, publish
from testbed.processes import overseer_command

HASH = bcrypt.hashpw(b"secret", bcrypt.gensalt(rounds=4)).decode()
INVENTORY = """
models:
  tb4:
    labels: {vendor: clearpath}
    expected:
      - /Power/Battery
      - {prefix: "/Wheels/", at_least: 2}
robots:
  site_a/r1: {model: tb4, labels: {site: site_a, team: ops}}
  site_a/ghost: {labels: {site: site_a}}
  site_b/r2: {model: tb4, labels: {site: site_b}}
"""
FAST = {"stale_after": "0.2s", "robot_timeout": "0.5s"}  # a robot heard once is down after 0.6 s
AS_BOB = {"Authorization": "Basic " + base64.b64encode(b"bob:secret").decode()}


def write(path: Path, text: str) -> str:
    path.write_text(text, encoding="utf-8")
    return str(path)


def samples(
    running: Exporter, name: str, headers: dict[str, str] | None = None
) -> dict[tuple[tuple[str, str], ...], float]:
    """Every sample of `name` on /metrics, by its sorted labels."""
    status, text = call(running, "/metrics", headers=headers)
    assert status == 200
    return {
        tuple(sorted(sample.labels.items())): sample.value
        for family in text_string_to_metric_families(text.decode())
        for sample in family.samples
        if sample.name == name
    }


def check(*args: str) -> subprocess.CompletedProcess[str]:
    """The installed check_ros_diagnostics, as Nagios runs it."""
    script = Path(overseer_command()[0]).with_name("check_ros_diagnostics")
    return subprocess.run([str(script), *args], capture_output=True, text=True, timeout=30, check=False)


def robots_command(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*overseer_command(), "robots", *args], capture_output=True, text=True, timeout=60, check=False
    )


def test_listed_robots_are_followed_from_the_start_with_their_labels_and_expected_components(
    tmp_path: Path,
) -> None:
    inventory = write(tmp_path / "inventory.yml", INVENTORY)
    with in_process_exporter(tmp_path, inventory={"file": inventory}) as running:
        publish(running, "site_a/r1", (0, "/Power/Battery", "ok"), (0, "/Wheels/left", "ok"))
        publish(running, "unlisted", (0, "/a", "ok"))
        info = samples(running, "ros_diagnostics_robot_info")
        up = samples(running, "ros_diagnostics_robot_up")
        heard = samples(running, "ros_diagnostics_robot_last_message_timestamp_seconds")
        levels = samples(running, "ros_diagnostics_level")
        status, ghost = call(running, "/api/v1/robots/site_a%2Fghost")
        _, r1 = call(running, "/api/v1/robots/site_a%2Fr1")
        _, site_a = call(running, "/api/v1/robots?label=site=site_a")
        _, both = call(running, "/api/v1/robots?label=site=site_a&label=team=ops")
        _, none = call(running, "/api/v1/robots?label=site=site_c")
        _, no_site = call(running, "/api/v1/robots?label=site=")
        bad_status, bad = call(running, "/api/v1/robots?label=site")
        ghost_check = check("--url", running.server.url, "-r", "site_a/ghost")
        r1_check = check("--url", running.server.url, "-r", "site_a/r1")
    assert info == {
        (
            ("model", "tb4"),
            ("robot", "site_a/r1"),
            ("site", "site_a"),
            ("team", "ops"),
            ("vendor", "clearpath"),
        ): 1,
        (("robot", "site_a/ghost"), ("site", "site_a")): 1,
        (("model", "tb4"), ("robot", "site_b/r2"), ("site", "site_b"), ("vendor", "clearpath")): 1,
        (("robot", "unlisted"),): 1,
    }
    assert up[(("robot", "site_a/ghost"),)] == 0 and up[(("robot", "site_a/r1"),)] == 1
    assert (("robot", "site_a/ghost"),) not in heard  # never heard: no last message at all
    wheels = (("component", "/Wheels/*"), ("hardware_id", ""), ("robot", "site_a/r1"))
    assert (
        levels[wheels] == 3
        and levels[(("component", "/Power/Battery"), ("hardware_id", ""), ("robot", "site_b/r2"))] == 3
    )
    assert (status, ghost["up"], ghost["down_reason"], ghost["listed"], ghost["last_message"]) == (
        200,
        False,
        "never_heard",
        True,
        None,
    )
    assert ghost["labels"] == {"site": "site_a"}
    stand_in = next(c for c in r1["components"] if c["name"] == "/Wheels/*")
    assert stand_in == {
        **stand_in,
        "state": "STALE",
        "reported": False,
        "expected": True,
        "last_update": None,
        "message": "expected at least 2 components matching /Wheels/*: 1 reported, 1 missing",
    }
    battery = next(c for c in r1["components"] if c["name"] == "/Power/Battery")
    assert (battery["reported"], battery["expected"], battery["state"]) == (True, True, "OK")
    assert [robot["robot"] for robot in site_a["robots"]] == ["site_a/ghost", "site_a/r1"]
    assert [robot["robot"] for robot in both["robots"]] == ["site_a/r1"] and none["robots"] == []
    assert [robot["robot"] for robot in no_site["robots"]] == ["unlisted"]  # as Prometheus's site=""
    assert bad_status == 400 and bad["error"] == "label: expected NAME=VALUE, got 'site'"
    assert ghost_check.returncode == 3
    assert ghost_check.stdout == "UNKNOWN - site_a/ghost is down: listed in the inventory, never heard\n"
    assert r1_check.returncode == 3
    stand_in_line = "/Wheels/*: expected at least 2 components matching /Wheels/*: 1 reported, 1 missing"
    assert stand_in_line in r1_check.stdout.splitlines()


def test_the_check_judges_a_site_as_one_group(tmp_path: Path) -> None:
    inventory = write(tmp_path / "inventory.yml", INVENTORY)
    with in_process_exporter(tmp_path, inventory={"file": inventory}) as running:
        publish(
            running, "site_a/r1", (2, "/Power/Battery", "dead"), (0, "/Wheels/l", "ok"), (0, "/Wheels/r", "")
        )
        publish(
            running, "site_b/r2", (0, "/Power/Battery", "ok"), (0, "/Wheels/l", "ok"), (0, "/Wheels/r", "")
        )
        url = ("--url", running.server.url)
        site_a = check(*url, "--label", "site=site_a")
        site_b = check(*url, "--label=site=site_b", "--label", "vendor=clearpath")
        nobody = check(*url, "--label", "site=mars")
        mixed = check(*url, "--label", "site=site_a", "-r", "site_a/r1")
    assert site_a.returncode == 2, site_a.stdout
    first, *rest = site_a.stdout.splitlines()
    assert first == (
        "CRITICAL - 2 robots with site=site_a: site_a/r1 (1 ERROR) (also 1 UNKNOWN) | 'robots'=2;;;0 "
        "'critical'=1;;;0 'warning'=0;;;0 'unknown'=1;;;0 'ok'=0;;;0 'down'=1;;;0 'maintenance'=0;;;0"
    )
    assert rest == [
        "CRITICAL robot(s) list:",
        "site_a/r1: 1 ERROR",
        "UNKNOWN robot(s) list:",
        "site_a/ghost: down: never heard, listed in the inventory",
    ]
    assert site_b.returncode == 0 and site_b.stdout.startswith(
        "OK - 1 robot with site=site_b, vendor=clearpath: 1 OK |"
    )
    assert nobody.returncode == 3 and nobody.stdout == "UNKNOWN - no robot with site=mars\n"
    assert mixed.returncode == 3 and "--label judges a group of robots" in mixed.stdout


def test_a_reload_takes_a_good_file_and_refuses_a_bad_one_keeping_the_old(tmp_path: Path) -> None:
    path = tmp_path / "inventory.yml"
    inventory = write(path, INVENTORY)
    with in_process_exporter(
        tmp_path, inventory={"file": inventory}, web={"enable_lifecycle": True}
    ) as running:
        before = samples(running, "overseer_inventory_last_reload_success_timestamp_seconds")
        write(path, INVENTORY + "  site_c/r3: {labels: {site: site_c}}\n")
        time.sleep(0.01)
        assert call(running, "/-/reload", "POST") == (200, {"reloaded": True})
        after = samples(running, "overseer_inventory_last_reload_success_timestamp_seconds")
        write(path, "robots:\n  site_a/r1: {labels: {job: x}}\n")
        status, refused = call(running, "/-/reload", "PUT")
        _, r3 = call(running, "/api/v1/robots/site_c%2Fr3")
        ok = samples(running, "overseer_inventory_last_reload_successful")
        listed = samples(running, "overseer_inventory_robots")
        still = samples(running, "overseer_inventory_last_reload_success_timestamp_seconds")
        wrong_method = call(running, "/-/reload")
    assert after[()] > before[()]
    assert (
        status == 500
        and refused["error"].startswith("failed to reload the inventory: inventory.file '")
        and refused["error"].endswith(
            "robots.site_a/r1.labels.job: 'job' is a label of Overseer's own series; name it otherwise"
        )
    )
    assert r3["labels"] == {"site": "site_c"}  # the inventory before the bad file stays
    assert (ok, listed, still) == ({(): 0.0}, {(): 4.0}, after)
    assert wrong_method[0] == 405


def test_reload_is_off_without_the_lifecycle_flag_as_prometheus_s(tmp_path: Path) -> None:
    inventory = write(tmp_path / "inventory.yml", INVENTORY)
    with in_process_exporter(tmp_path, inventory={"file": inventory}) as running:
        status, answer = call(running, "/-/reload", "POST")
    assert status == 403 and "--web.enable-lifecycle" in answer["error"]


def test_a_bad_inventory_at_start_is_a_configuration_error(tmp_path: Path) -> None:
    inventory = write(tmp_path / "inventory.yml", "robots:\n  r1: {model: nope}\n")
    done = subprocess.run(
        [*overseer_command(), "run", f"--inventory.file={inventory}", "--dds.disabled"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    assert done.returncode == 2
    assert done.stderr == (
        f"overseer run: configuration error: inventory.file {inventory!r}: robots.r1.model: unknown model "
        "'nope' (known: none in models:)\n"
    )


def retiring_exporter(tmp_path: Path, **sections: Any) -> Any:
    web_config = write(tmp_path / "web.yml", f"basic_auth_users:\n  alice: '{HASH}'\n  bob: '{HASH}'\n")
    return in_process_exporter(
        tmp_path,
        web={"config_file": web_config, "enable_maintenance_api": True},
        maintenance={"writers": ["alice"]},
        fleet=FAST,
        **sections,
    )


@contextmanager
def keeps_publishing(running: Exporter, robot: str) -> Iterator[None]:
    """`robot` publishes every 0.1 s until the block ends: up however slow the machine is."""
    stop = threading.Event()

    def loop() -> None:
        while not stop.wait(0.1):
            publish(running, robot, (0, "/a", "ok"))

    publish(running, robot, (0, "/a", "ok"))
    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


def test_retiring_forgets_a_robot_that_is_down_and_not_listed_and_says_who(tmp_path: Path) -> None:
    inventory = write(tmp_path / "inventory.yml", INVENTORY)
    alice = write(tmp_path / "alice", "alice:secret\n")
    with (
        retiring_exporter(tmp_path, inventory={"file": inventory}) as running,
        keeps_publishing(running, "alive"),
    ):
        publish(running, "dead", (0, "/a", "ok"))
        publish(running, "site_a/r1", (0, "/Power/Battery", "ok"))
        time.sleep(0.8)
        url = ("--url", running.server.url, "--authorization-file", alice)
        as_bob = robots_command("retire", "dead", "--url", running.server.url, "-a", "bob:secret")
        refused = robots_command("retire", "alive", "site_a/r1", "nobody", *url)
        retired = robots_command("retire", "dead", "-c", "sold to a museum", *url)
        forgotten = samples(running, "overseer_robots_forgotten_total", AS_BOB)
        status, _ = call(running, "/api/v1/robots/dead", headers=AS_BOB)
        assert running.history is not None
        running.history.store.flush()
        _, events = call(running, "/api/v1/events?robot=dead", headers=AS_BOB)
    assert (
        as_bob.returncode == 1 and "user 'bob' may not retire robots (maintenance.writers)" in as_bob.stderr
    )
    assert refused.returncode == 1
    assert refused.stderr.splitlines() == [
        f"overseer robots retire: alive: HTTP 409 from {running.server.url}/api/v1/retirements: "
        "robot 'alive' is up: only a robot that is down can be retired",
        f"overseer robots retire: site_a/r1: HTTP 409 from {running.server.url}/api/v1/retirements: "
        "robot 'site_a/r1' is in the inventory: remove it there (and reload) to forget it",
        f"overseer robots retire: nobody: HTTP 404 from {running.server.url}/api/v1/retirements: no robot "
        "'nobody' is followed",
    ]
    assert retired.returncode == 0 and retired.stdout == "dead: retired by alice: sold to a museum\n"
    assert forgotten[(("reason", "retired"),)] == 1 and status == 404
    assert (events["events"][0]["kind"], events["events"][0]["message"]) == (
        "retired",
        "retired by alice: sold to a museum",
    )


def test_overseer_robots_lists_and_checks(tmp_path: Path) -> None:
    inventory = write(tmp_path / "inventory.yml", INVENTORY)
    bad = write(tmp_path / "bad.yml", "robots:\n  r1: {labels: {le: x}}\n")
    with in_process_exporter(tmp_path, inventory={"file": inventory}) as running:
        publish(running, "site_a/r1", (0, "/Power/Battery", "ok"))
        listing = robots_command("list", "--url", running.server.url, "--label", "site=site_a")
        as_json = robots_command("list", "--url", running.server.url, "--down", "--json")
    checked, refused = robots_command("check", inventory), robots_command("check", bad)
    assert listing.returncode == 0, listing.stderr
    header, ghost, r1 = listing.stdout.splitlines()
    assert header.split() == ["ROBOT", "STATE", "UP", "INVENTORY", "LABELS"]
    assert ghost.split() == ["site_a/ghost", "STALE", "down:", "never", "heard", "listed", "site=site_a"]
    assert r1.split() == [
        "site_a/r1",
        "STALE",
        "up",
        "listed",
        "model=tb4,site=site_a,team=ops,vendor=clearpath",
    ]
    assert [robot["robot"] for robot in json.loads(as_json.stdout)["robots"]] == ["site_a/ghost", "site_b/r2"]
    assert (
        checked.returncode == 0
        and checked.stdout == f"{inventory}: 3 robots, 4 expected components in all: OK\n"
    )
    assert (
        refused.returncode == 1
        and "robots.r1.labels.le: 'le' is a label of Overseer's own series" in refused.stderr
    )
