"""Real Zenoh for tests: a router in its own process, and a client session for publishing by hand."""

from __future__ import annotations

import json
import socket
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import zenoh

from testbed.paths import REPO
from testbed.ports import free_port
from testbed.processes import RunningProcess, spawn


def endpoint(port: int) -> str:
    """The loopback TCP endpoint of a router on `port`."""
    return f"tcp/127.0.0.1:{port}"


def start_router(
    tmp_path: Path, port: int, timeout: float = 20.0, zenoh_defaults: bool = False
) -> RunningProcess:
    """Start a router listening on 127.0.0.1:`port` and wait until it accepts connections.

    It runs with the shipped router configuration, or with Zenoh's defaults when `zenoh_defaults`.
    """
    log_path = tmp_path / f"zenoh-router-{port}-{time.monotonic_ns()}.log"
    # As a module, not a script: a script's own folder would shadow the zenoh package with this file.
    args = [sys.executable, "-m", "testbed.zenoh_router", str(port)]
    args += ["--zenoh-defaults"] if zenoh_defaults else []
    router = RunningProcess(spawn(args, log_path, env={"PYTHONPATH": str(REPO)}), log_path)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if router.process.poll() is not None:
            raise RuntimeError(f"Zenoh router exited with {router.process.returncode}:\n{router.log()}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return router
        except OSError:
            time.sleep(0.1)
    router.stop()
    raise TimeoutError(f"Zenoh router not listening after {timeout}s:\n{router.log()}")


@contextmanager
def running_router(tmp_path: Path, port: int | None = None) -> Iterator[int]:
    """A router on a free loopback port (or `port`) for the block; yields its port."""
    port = port or free_port()
    router = start_router(tmp_path, port)
    try:
        yield port
    finally:
        router.stop()


@contextmanager
def running_router_process(
    tmp_path: Path, zenoh_defaults: bool = False
) -> Iterator[tuple[int, RunningProcess]]:
    """A router on a free loopback port for the block; yields its port and its process (for its CPU)."""
    port = free_port()
    router = start_router(tmp_path, port, zenoh_defaults=zenoh_defaults)
    try:
        yield port, router
    finally:
        router.stop()


@contextmanager
def client_session(port: int) -> Iterator[zenoh.Session]:
    """A Zenoh client session of the router on `port`, in this process, for publishing hand-made keys."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("client"))
    config.insert_json5("connect/endpoints", json.dumps([endpoint(port)]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    try:
        yield session
    finally:
        session.close()  # type: ignore[no-untyped-call]


def simulator_args(port: int, *extra: str) -> tuple[str, ...]:
    """`overseer simulate` flags publishing over Zenoh through the router on `port`, on loopback only."""
    return (
        "--transport=zenoh",
        f"--zenoh.connect={endpoint(port)}",
        "--zenoh.listen=tcp/127.0.0.1:0",
        *extra,
    )


def exporter_args(port: int, *extra: str) -> tuple[str, ...]:
    """`overseer run` flags following Zenoh robots through the router on `port`, with DDS off."""
    return ("--dds.disabled", f"--zenoh.connect={endpoint(port)}", *extra)
