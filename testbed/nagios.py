"""Nagios plugin results and a real Nagios 4 server, plus the fleet the check's end-to-end tests share.

Everything here speaks the plugin format (`STATE - text | perfdata` and long output), which the check,
Nagios and Icinga 2 all share: each server's view of a check result is rebuilt into that format.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from testbed.paths import REPO
from testbed.processes import VENV_BIN, Exporter, running_exporter, running_simulator, wait_for

NAGIOS_DEPLOY = REPO / "deploy" / "nagios"
NAGIOS4 = "/usr/sbin/nagios4"
CHECK_SCRIPT = VENV_BIN / "check_ros_diagnostics"

# The fleet of the check's end-to-end tests: one robot per outcome (tests/support/check_cases.py).
FLEET_EXPORTER_ARGS = ("--fleet.stale-after=4s", "--fleet.robot-timeout=6s")
FLEET_SIMULATOR_ARGS = (
    "--robots=4",
    "--warn=0",
    "--error=0",
    "--rate=2",
    "--event=1:robot2:/Camera/Cam2:WARN",
    "--event=1:robot2:/Temp/Sensor1:silence",
    "--event=1:robot3:/Laser/Laser2:ERROR",
    "--event=1:robot3:/Power/Robot Battery:WARN",
    "--event=2:robot4:stop",
)


@dataclass(frozen=True)
class PluginResult:
    """A check result: exit status and the full plugin output (status line with perfdata, long output)."""

    state: int
    output: str


def run_check(*args: str, timeout: float = 30.0) -> PluginResult:
    """Run the installed `check_ros_diagnostics` with `args` as Nagios would."""
    done = subprocess.run([str(CHECK_SCRIPT), *args], capture_output=True, timeout=timeout, check=False)
    assert done.stderr == b"", done.stderr.decode(errors="replace")
    return PluginResult(done.returncode, done.stdout.decode("utf-8"))


def check_until(state: int, *args: str, timeout: float = 60.0) -> PluginResult:
    """Run the check until it exits with `state` (a loaded machine may delay a robot's messages)."""
    results: list[PluginResult] = []

    def reached() -> bool:
        results.append(run_check(*args))
        return results[-1].state == state

    try:
        wait_for(reached, timeout=timeout, interval=0.5, message=f"exit status {state} from {args}")
    except AssertionError as error:
        raise AssertionError(f"{error}; last output:\n{results[-1].output}") from None
    return results[-1]


def join_output(text: str, perfdata: str, long_output: str) -> str:
    """Rebuild a plugin's output from a server's parts: status text, perfdata, long output."""
    first_line = text.rstrip() + (f" | {perfdata}" if perfdata else "")
    return first_line + (f"\n{long_output}" if long_output else "")


def fleet_is_ready(exporter: Exporter) -> bool:
    """Whether the exporter shows every robot of the fleet in the state CASES expect."""
    robots = {robot["robot"]: robot for robot in exporter.get_json("/api/v1/robots")["robots"]}
    if len(robots) != 4:
        return False
    counts = {name: robot["counts"] for name, robot in robots.items()}
    return bool(
        robots["robot1"]["up"]
        and robots["robot1"]["level"] == 0
        and counts["robot2"]["warn"] == 2
        and counts["robot2"]["stale"] == 1
        and counts["robot3"]["error"] == 2
        and counts["robot3"]["warn"] == 2
        and not robots["robot4"]["up"]
    )


@contextmanager
def running_fleet(tmp_path: Path, domain: int) -> Iterator[Exporter]:
    """A real exporter fed by the simulated fleet of CASES, once every robot has reached its state."""
    with (
        running_exporter(tmp_path, domain, *FLEET_EXPORTER_ARGS) as exporter,
        running_simulator(tmp_path, domain, *FLEET_SIMULATOR_ARGS) as simulator,
    ):
        try:
            wait_for(lambda: fleet_is_ready(exporter), timeout=60, message="the fleet's states")
        except AssertionError as error:
            raise AssertionError(
                f"{error}\nexporter:\n{exporter.log()}\nsimulator:\n{simulator.log()}"
            ) from None
        yield exporter


@dataclass
class Nagios:
    """A running Nagios 4 in a temporary directory, reporting through its status file."""

    process: subprocess.Popen[bytes]
    root: Path

    def services(self) -> dict[tuple[str, str], PluginResult]:
        """The last result of every checked service, by (host, service description)."""
        status_path = self.root / "var" / "status.dat"
        results = {}
        for block in status_blocks(status_path.read_text(encoding="utf-8", errors="replace")):
            if block.get("_type") == "servicestatus" and block.get("has_been_checked") == "1":
                output = join_output(
                    block["plugin_output"], block["performance_data"], block["long_plugin_output"]
                )
                results[(block["host_name"], block["service_description"])] = PluginResult(
                    int(block["current_state"]), output
                )
        return results

    def log(self) -> str:
        """Nagios's own log."""
        return (self.root / "var" / "nagios.log").read_text(encoding="utf-8", errors="replace")


def status_blocks(text: str) -> Iterator[dict[str, str]]:
    """The `type { key=value ... }` blocks of a Nagios status.dat, values unescaped; `_type` is the type."""
    block: dict[str, str] | None = None
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.endswith("{"):
            block = {"_type": stripped[:-1].strip()}
        elif stripped == "}" and block is not None:
            yield block
            block = None
        elif block is not None and "=" in stripped:
            key, _, value = stripped.partition("=")
            block[key] = unescape_status(value)


def unescape_status(value: str) -> str:
    """Undo status.dat's escaping of backslashes and newlines."""
    return re.sub(r"\\(.)", lambda match: "\n" if match.group(1) == "n" else match.group(1), value)


def write_nagios_config(root: Path, objects: str) -> Path:
    """A main nagios.cfg under `root` that loads the shipped deploy/nagios files and `objects`.

    $USER1$ points at the environment's bin directory, so the shipped command runs this
    checkout's check_ros_diagnostics.
    """
    for directory in ("var", "spool"):
        (root / directory).mkdir(parents=True, exist_ok=True)
    (root / "objects.cfg").write_text(objects, encoding="utf-8")
    (root / "resource.cfg").write_text(f"$USER1$={VENV_BIN}\n", encoding="utf-8")
    shipped = "\n".join(f"cfg_file={path}" for path in sorted(NAGIOS_DEPLOY.glob("*.cfg")))
    settings = {
        "log_file": root / "var" / "nagios.log",
        "object_cache_file": root / "var" / "objects.cache",
        "precached_object_file": root / "var" / "objects.precache",
        "resource_file": root / "resource.cfg",
        "status_file": root / "var" / "status.dat",
        "lock_file": root / "var" / "nagios.lock",
        "temp_file": root / "var" / "nagios.tmp",
        "temp_path": root / "var",
        "check_result_path": root / "spool",
        "state_retention_file": root / "var" / "retention.dat",
        "query_socket": root / "var" / "nagios.qh",
        "command_file": root / "var" / "nagios.cmd",
        "nagios_user": "root",
        "nagios_group": "root",
        "status_update_interval": 1,
        "check_external_commands": 0,
        "retain_state_information": 0,
        "use_syslog": 0,
        "interval_length": 1,
        "service_inter_check_delay_method": "n",
        "max_service_check_spread": 1,
        "host_inter_check_delay_method": "n",
        "max_host_check_spread": 1,
        "check_result_reaper_frequency": 1,
        "enable_notifications": 0,
        "enable_event_handlers": 0,
        "enable_flap_detection": 0,
        "check_for_updates": 0,
        "illegal_object_name_chars": "`~!$%^&*|'\"<>?,()=",
        "illegal_macro_output_chars": "`~$&|'\"<>",
    }
    lines = [
        shipped,
        f"cfg_file={root / 'objects.cfg'}",
        *(f"{key}={value}" for key, value in settings.items()),
    ]
    main_config = root / "nagios.cfg"
    main_config.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return main_config


def validate_nagios_config(main_config: Path) -> subprocess.CompletedProcess[str]:
    """`nagios4 -v` on `main_config`."""
    return subprocess.run([NAGIOS4, "-v", str(main_config)], capture_output=True, text=True, timeout=60)


@contextmanager
def running_nagios(root: Path, objects: str) -> Iterator[Nagios]:
    """Run Nagios 4 with the shipped definitions and `objects` until the block ends, then stop it."""
    main_config = write_nagios_config(root, objects)
    log = (root / "nagios.out").open("wb")
    process = subprocess.Popen(
        [NAGIOS4, str(main_config)], stdout=log, stderr=subprocess.STDOUT, start_new_session=True
    )
    log.close()
    nagios = Nagios(process, root)
    try:
        wait_for(lambda: (root / "var" / "status.dat").exists() or process.poll() is not None, timeout=30)
        if process.poll() is not None:
            raise RuntimeError(f"nagios4 exited with {process.returncode}:\n{nagios_output(root)}")
        yield nagios
    finally:
        stop_process_group(process)


def nagios_output(root: Path) -> str:
    """What the nagios4 process printed."""
    return (root / "nagios.out").read_text(encoding="utf-8", errors="replace")


def stop_process_group(process: subprocess.Popen[bytes], timeout: float = 15.0) -> None:
    """SIGTERM a server started in its own session; SIGKILL its process group if any of it lingers."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    deadline = time.monotonic() + timeout
    while live_group_members(process.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    if live_group_members(process.pid):
        os.killpg(process.pid, signal.SIGKILL)


def live_group_members(group: int) -> list[int]:
    """Process ids in process group `group` that are still running (zombies do not count)."""
    members = []
    for stat_path in Path("/proc").glob("[0-9]*/stat"):
        try:
            state, _parent, process_group = stat_path.read_text().rpartition(")")[2].split()[:3]
        except OSError:
            continue
        if int(process_group) == group and state != "Z":
            members.append(int(stat_path.parent.name))
    return members
