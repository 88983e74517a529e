"""A stop sent while a command starts its parts is kept until it waits for one, not the default action.

As systemd stops a service (SIGTERM to every process of its group), a stop can come before `overseer run`
or `overseer demo` waits for it: with the default action still in place, it ended the process with its
parts half started (exit -15 instead of a clean stop). Each scenario runs in a child process: the
signals are its own.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

from testbed.ports import free_port
from testbed.processes import RunningProcess, overseer_command, spawn, wait_for

_STOPPED_WHILE_STARTING = """
import os, signal, sys, time
from overseer.commands.signals import StopSignals

hangups = []
signals = StopSignals(lambda: hangups.append(1))
os.kill(os.getpid(), signal.SIGHUP)   # while starting: read the files again once it waits
os.kill(os.getpid(), signal.SIGTERM)  # while starting: kept, not the default action
time.sleep(0.3)                       # the parts starting
started = time.monotonic()
signals.wait()
print("waited", round(time.monotonic() - started, 1), "hangups", len(hangups))
"""

_SECOND_STOP = """
import os, signal
from overseer.commands.signals import StopSignals

signals = StopSignals()
os.kill(os.getpid(), signal.SIGTERM)
signals.wait()
print("stopping", flush=True)
os.kill(os.getpid(), signal.SIGTERM)  # a second one while stopping: leave at once
print("not reached")
"""


def run_script(script: str) -> subprocess.CompletedProcess[str]:
    """Run `script` in a Python child process of this interpreter."""
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=30)


def test_a_stop_sent_before_the_wait_is_kept_and_the_wait_returns_at_once() -> None:
    done = run_script(_STOPPED_WHILE_STARTING)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["waited", "0.0", "hangups", "0"]  # stopped before any SIGHUP was read


def test_a_second_stop_while_stopping_leaves_at_once() -> None:
    done = run_script(_SECOND_STOP)
    assert done.returncode == 128 + 15, done.stderr
    assert done.stdout.split() == ["stopping"]


@pytest.mark.servers
@pytest.mark.parametrize("command", ["run", "demo"])
def test_a_stop_sent_while_the_command_starts_its_parts_ends_it_cleanly(
    command: str, tmp_path: Path, dds_domain: int
) -> None:
    """The stop comes as the event history opens, before the workers, the server and the sources start."""
    domain = (
        [f"--dds.domain={dds_domain}", "--dds.loopback-only"]
        if command == "run"
        else [f"--domain={dds_domain}"]
    )
    for attempt in range(3):  # a loaded machine may finish starting before the stop is sent: try again
        args = [*overseer_command(), command, f"--web.listen-address=127.0.0.1:{free_port()}", *domain]
        if stopped_while_starting(args, tmp_path / f"{command}-{attempt}.log"):
            return
    pytest.fail("the command had started its parts each time before the stop was sent")


def stopped_while_starting(args: list[str], log_path: Path) -> bool:
    """Run `args`, stop it as its event history opens, check it stopped cleanly: whether it was starting."""
    process = RunningProcess(spawn(args, log_path), log_path)
    try:
        wait_for(lambda: "recording fleet events" in process.log(), 30, interval=0.01, message="starting")
        started = "serving on" in process.log()  # it may still finish before the stop lands: rarely
        process.process.send_signal(signal.SIGTERM)
        assert process.process.wait(30) == 0, process.log()
        assert "INFO overseer: stopping" in process.log()
    finally:
        process.stop()
    return not started
