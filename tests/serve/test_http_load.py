"""Slow and many HTTP clients cannot starve ingest: bounded connections, request slots and deadlines.

50 simulated robots x 25 components publish at 5 Hz (250 messages a second) while 20 scrapers pull
/metrics as fast as they can and a slow client trickles a request. Nothing may be lost: the exporter's
`received` counter must equal what the simulator reports it published (it waits for the exporter's
readers before its first message, and prints its count when stopped), and as it runs with stale_after
1 s, ingest held up for a second would show as STALE components in a scrape.
"""

from __future__ import annotations

import contextlib
import re
import select
import socket
import statistics
import threading
import time
import urllib.request
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import pytest

import overseer.serve.http
from overseer.messages import DiagnosticArray
from overseer.model import FleetLimits, FleetModel
from overseer.serve.http import (
    MAX_CONCURRENT_REQUESTS,
    MAX_CONNECTIONS,
    REQUEST_TIMEOUT_SECONDS,
    OverseerServer,
)
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components
from testbed.model_server import serving
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for
from testbed.scrapes import Scrape, parse_scrape

ROBOTS, COMPONENTS_PER_ROBOT, RATE_HZ = 50, 25, 5.0  # --components=20 leaves plus 5 group statuses
SCRAPERS, LOAD_SECONDS = 20, 20.0
EXPORTER_FLAGS = ("--fleet.stale-after=1s", "--fleet.robot-timeout=2s", "--log.level=warning")
SIMULATOR_FLAGS = (
    f"--robots={ROBOTS}",
    "--components=20",
    f"--rate={RATE_HZ:g}",
    "--wait-for-subscribers=60",
)


def fetch_metrics(exporter: Exporter, timeout: float = 10.0) -> str:
    """The text of GET /metrics."""
    with urllib.request.urlopen(exporter.url + "/metrics", timeout=timeout) as response:
        return str(response.read().decode("utf-8"))


def scrape(exporter: Exporter) -> Scrape:
    """One /metrics scrape, parsed."""
    return parse_scrape(fetch_metrics(exporter))


def fleet_whole(exporter: Exporter) -> Scrape | None:
    """The scrape, once every robot is up with every component and none is stale."""
    result = scrape(exporter)
    whole = result.robots_up == ROBOTS and result.components == ROBOTS * COMPONENTS_PER_ROBOT
    return result if whole and result.stale_components == 0 else None


@dataclass(frozen=True)
class Outcome:
    """What the simulator published and what the exporter received, once the simulator stopped."""

    published: int
    received: float
    lost: float


@contextmanager
def loaded_fleet(tmp_path: Path, domain: int, outcome: list[Outcome]) -> Iterator[Exporter]:
    """The exporter with the full-rate fleet, once whole; appends the count of messages to `outcome`."""
    with (
        running_exporter(tmp_path, domain, *EXPORTER_FLAGS) as exporter,
        running_simulator(tmp_path, domain, *SIMULATOR_FLAGS) as simulator,
    ):
        wait_for(lambda: fleet_whole(exporter), 60, interval=0.5, message="the whole fleet up")
        yield exporter
        assert simulator.stop() == 0
        match = re.search(r"published (\d+) messages", simulator.log())
        assert match is not None, simulator.log()
        published = int(match.group(1))
        deadline = time.monotonic() + 5  # the last messages may still be on their way
        while (final := scrape(exporter)).received < published and time.monotonic() < deadline:
            time.sleep(0.1)
        outcome.append(Outcome(published, final.received, final.lost))


@dataclass
class ScrapeLog:
    """Every scrape of the load phase: latencies and what went wrong."""

    latencies: list[float] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def scrape_until(self, exporter: Exporter, deadline: float) -> None:
        """Scrape back to back until `deadline`, recording each result."""
        while time.monotonic() < deadline:
            started = time.monotonic()
            try:
                text = fetch_metrics(exporter)
                fetched = time.monotonic()
                result = parse_scrape(text)
                problem = ""
                if result.robots_up != ROBOTS or result.stale_components or result.lost:
                    problem = f"unhealthy fleet in a scrape: {result}"
            except Exception as error:  # any failure of a scrape is what this test looks for
                fetched, problem = time.monotonic(), f"{type(error).__name__}: {error}"
            with self.lock:
                self.latencies.append(fetched - started)
                if problem:
                    self.failures.append(problem)


def trickle_request(host: str, port: int, results: dict[str, float]) -> None:
    """Send a request one byte every half second; record when the server hung up (seconds)."""
    started = time.monotonic()
    with socket.create_connection((host, port), timeout=5) as sock:
        for byte in b"GET /metrics HTTP/1.1\r\nHost: x\r\nX-Padding: " + b"x" * 200:
            readable = select.select([sock], [], [], 0.5)[0]
            try:
                if readable and not sock.recv(4096):
                    break
                sock.send(bytes([byte]))
            except ConnectionError:
                break
        results["trickle"] = time.monotonic() - started


@pytest.mark.servers
def test_twenty_scrapers_and_slow_clients_lose_no_update_at_full_rate(
    tmp_path: Path, dds_domain: int
) -> None:
    outcome: list[Outcome] = []
    with loaded_fleet(tmp_path, dds_domain, outcome) as exporter:
        host, port = exporter.url.removeprefix("http://").split(":")
        log = ScrapeLog()
        slow: dict[str, float] = {}
        before, t0 = scrape(exporter), time.monotonic()
        deadline = t0 + LOAD_SECONDS
        threads = [
            threading.Thread(target=log.scrape_until, args=(exporter, deadline)) for _ in range(SCRAPERS)
        ]
        threads.append(threading.Thread(target=trickle_request, args=(host, int(port), slow)))
        for thread in threads:
            thread.start()
        for thread in threads[:SCRAPERS]:
            thread.join(LOAD_SECONDS + 30)
        after, t1 = scrape(exporter), time.monotonic()
        for thread in threads[SCRAPERS:]:
            thread.join(60)

    expected = ROBOTS * RATE_HZ * (t1 - t0)
    during = after.received - before.received
    [total] = outcome
    print(
        f"\nload: {len(log.latencies)} scrapes by {SCRAPERS} scrapers in {LOAD_SECONDS:g}s, fetch median "
        f"{statistics.median(log.latencies) * 1000:.0f} ms, max {max(log.latencies) * 1000:.0f} ms; "
        f"{during:.0f} messages received under load ({during / expected:.1%} of robots x rate x time); "
        f"{total.received:.0f} received of {total.published} published in all; "
        f"trickling client cut off after {slow.get('trickle', -1):.1f}s; {len(log.failures)} failed scrapes"
    )
    assert log.failures == []
    assert len(log.latencies) >= SCRAPERS * 2
    assert total.received == total.published and total.lost == 0
    assert during >= 0.95 * expected  # the schedule held under load, not only caught up afterwards
    assert REQUEST_TIMEOUT_SECONDS - 1 <= slow["trickle"] <= REQUEST_TIMEOUT_SECONDS + 3


@pytest.mark.servers
def test_a_flood_of_idle_connections_is_capped_and_cleared_without_touching_ingest(
    tmp_path: Path, dds_domain: int
) -> None:
    outcome: list[Outcome] = []
    with loaded_fleet(tmp_path, dds_domain, outcome) as exporter, ExitStack() as stack:
        host, port = exporter.url.removeprefix("http://").split(":")
        before, started = scrape(exporter), time.monotonic()
        flood = [
            stack.enter_context(socket.create_connection((host, int(port)), timeout=5))
            for _ in range(MAX_CONNECTIONS + 72)
        ]
        # Past the cap, connections are closed at once rather than given a thread each.
        wait_for(
            lambda: sum(1 for sock in flood if select.select([sock], [], [], 0)[0]) >= 72,
            5,
            message="connections past the cap closed",
        )
        # The held ones are cut at the deadline, and scrapes work again, with a fleet that never went stale.
        result = wait_for(
            lambda: fleet_whole(exporter), REQUEST_TIMEOUT_SECONDS + 10, message="scrapes again"
        )
        elapsed = time.monotonic() - started
        assert all(not sock.recv(1) for sock in flood)
        assert result.received - before.received >= 0.95 * ROBOTS * RATE_HZ * elapsed
    [total] = outcome
    assert total.received == total.published and total.lost == 0


@contextmanager
def in_process_server(robots: int) -> Iterator[OverseerServer]:
    """An OverseerServer on loopback in this process, serving `robots` robots of 25 components."""
    model = FleetModel(FleetLimits(stale_after=3600, robot_timeout=3600))
    leaves = leaf_components(20)
    array = DiagnosticArray(0, 0, "", tuple(aggregated_statuses(leaves, initial_levels(leaves, 1, 1), set())))
    for index in range(robots):
        model.apply(f"robot{index}", array, "dds")
    with serving(model) as server:
        yield server


def test_a_client_that_never_reads_its_answer_is_cut_off_at_the_deadline(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(overseer.serve.http, "REQUEST_TIMEOUT_SECONDS", 1.0)
    with in_process_server(robots=3000) as server, socket.socket() as sock:  # about 24 MB of /metrics
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect(server.server_address[:2])
        sock.sendall(b"GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n")
        time.sleep(3)  # the window stays full, so the server's writes block
        sock.settimeout(10)
        answer = bytearray()
        with contextlib.suppress(ConnectionError):
            while chunk := sock.recv(1 << 20):
                answer += chunk
        slots_free = all(server.slots.acquire(blocking=False) for _ in range(MAX_CONCURRENT_REQUESTS))
    head, _, body = bytes(answer).partition(b"\r\n\r\n")
    length = int(head.lower().split(b"content-length: ")[1].split(b"\r\n")[0])
    assert length > 20_000_000
    assert len(body) < length  # cut off after the deadline, not held until the client reads
    assert slots_free  # and its request slot was given back
