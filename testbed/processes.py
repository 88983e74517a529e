"""Start the project's own commands (exporter, simulator) as real processes, and always stop them."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import quote

from prometheus_client.parser import text_string_to_metric_families

from testbed.ports import free_port

VENV_BIN = Path(sys.executable).parent


def overseer_command() -> list[str]:
    """The `overseer` console script of the environment running the tests."""
    script = VENV_BIN / "overseer"
    return [str(script)] if script.exists() else [sys.executable, "-m", "overseer.cli"]


@dataclass
class RunningProcess:
    """A started process with the log file its output goes to."""

    process: subprocess.Popen[bytes]
    log_path: Path

    def log(self) -> str:
        """Everything the process printed so far."""
        return self.log_path.read_text(encoding="utf-8", errors="replace")

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int:
        """Stop the process (SIGKILL after `timeout`) and return its exit code."""
        if self.process.poll() is None:
            self.process.send_signal(sig)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        return self.process.returncode


@dataclass
class Exporter(RunningProcess):
    """A running `overseer run` and its base URL."""

    url: str

    def get(self, path: str, timeout: float = 5.0) -> bytes:
        """The body of GET `path`."""
        with urllib.request.urlopen(self.url + path, timeout=timeout) as response:
            body: bytes = response.read()
            return body

    def get_json(self, path: str) -> Any:
        """GET `path` parsed as JSON."""
        return json.loads(self.get(path))

    def samples(self) -> dict[str, dict[tuple[tuple[str, str], ...], float]]:
        """The samples of /metrics by metric name, keyed by their sorted labels."""
        result: dict[str, dict[tuple[tuple[str, str], ...], float]] = {}
        for family in text_string_to_metric_families(self.get("/metrics").decode()):
            for sample in family.samples:
                result.setdefault(sample.name, {})[tuple(sorted(sample.labels.items()))] = sample.value
        return result

    def robot(self, name: str) -> dict[str, Any] | None:
        """The API's view of one robot, or None while it is unknown."""
        try:
            result: dict[str, Any] = self.get_json("/api/v1/robots/" + quote(name, safe="/"))
            return result
        except urllib.error.HTTPError as error:
            if error.code == 404:
                return None
            raise


def spawn(
    args: Sequence[str], log_path: Path, env: dict[str, str] | None = None, cwd: Path | None = None
) -> subprocess.Popen[bytes]:
    """Start `args` in its own session with stdout and stderr going to `log_path`.

    It runs in `cwd`, by default the log's directory (the test's own), so that files a program makes in
    its working directory (the exporter's event database) never land in the repository.
    """
    log = log_path.open("wb")
    try:
        return subprocess.Popen(
            list(args),
            stdout=log,
            stderr=subprocess.STDOUT,
            env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})},
            start_new_session=True,
            cwd=log_path.parent if cwd is None else cwd,
        )
    finally:
        log.close()


@contextmanager
def running_exporter(
    tmp_path: Path,
    domain: int | None,
    *extra_args: str,
    port: int | None = None,
    timeout: float = 30.0,
    command: Sequence[str] | None = None,
    env: dict[str, str] | None = None,
    loopback_flag: bool = True,
) -> Iterator[Exporter]:
    """Run `overseer run` on loopback, joined to `domain` (None: as configured), until the block ends.

    It runs in `tmp_path`, so its files (the event history's database) stay with the test. `command` is
    another installation's `overseer` script, `env` what to add to its environment. `loopback_flag` False
    leaves out `--dds.loopback-only` (the environment says so).
    """
    port = port or free_port()
    args = [
        *(command or overseer_command()),
        "run",
        f"--web.listen-address=127.0.0.1:{port}",
        *([f"--dds.domain={domain}"] if domain is not None else []),
        *(["--dds.loopback-only"] if loopback_flag else []),
        *extra_args,
    ]
    log_path = tmp_path / f"exporter-{port}.log"
    exporter = Exporter(spawn(args, log_path, env=env, cwd=tmp_path), log_path, f"http://127.0.0.1:{port}")
    try:
        wait_until_healthy(exporter, timeout)
        yield exporter
    finally:
        exporter.stop()


def wait_until_healthy(exporter: Exporter, timeout: float) -> None:
    """Wait for /-/healthy to answer 200, failing early if the process dies."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if exporter.process.poll() is not None:
            raise RuntimeError(f"exporter exited with {exporter.process.returncode}:\n{exporter.log()}")
        try:
            exporter.get("/-/healthy", timeout=1.0)
            return
        except urllib.error.HTTPError as error:
            if error.code == 401:  # serving, behind basic auth
                return
            time.sleep(0.1)
        except (urllib.error.URLError, ConnectionError, TimeoutError):
            time.sleep(0.1)
    raise TimeoutError(f"exporter not healthy after {timeout}s:\n{exporter.log()}")


@contextmanager
def running_simulator(tmp_path: Path, domain: int, *extra_args: str) -> Iterator[RunningProcess]:
    """Run `overseer simulate` on loopback in `domain` until the block ends."""
    args = [*overseer_command(), "simulate", f"--domain={domain}", "--dds.loopback-only", *extra_args]
    log_path = tmp_path / f"simulator-{time.monotonic_ns()}.log"
    simulator = RunningProcess(spawn(args, log_path), log_path)
    try:
        yield simulator
    finally:
        simulator.stop()


def wait_for(predicate: Any, timeout: float, interval: float = 0.2, message: str = "condition") -> Any:
    """Poll `predicate` until it returns something truthy; return that, or fail after `timeout`."""
    deadline = time.monotonic() + timeout
    last_error: Exception | None = None
    while time.monotonic() < deadline:
        try:
            result = predicate()
            if result:
                return result
        except (urllib.error.URLError, ConnectionError, TimeoutError, KeyError, ValueError) as error:
            last_error = error
        time.sleep(interval)
    raise AssertionError(f"timed out after {timeout}s waiting for {message} (last error: {last_error})")
