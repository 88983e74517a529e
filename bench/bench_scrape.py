"""Scrape: what Prometheus records scraping the exporter, in the format it asks for, beside the floor.

Two parts, in one run:

- **A real Prometheus** (Debian's, with its own Accept header and gzip, scraping every 5 s) scrapes an
  exporter that follows 1,000 simulated robots x 50 components over DDS on loopback, with one ingest
  worker and with two, and in the same Prometheus a static server answering the exporter's own
  exposition bytes (the floor: Prometheus's parsing and storing, which no exporter can avoid), gzipped
  whole, and another answering the same text gzipped as the exporter sends it (its robots' pieces laid
  end to end: what that costs Prometheus to unzip). We read Prometheus's own `scrape_duration_seconds`,
  then time curl with Prometheus's header and with the text format's, plain and gzip, and the exporter's
  CPU for one scrape (its process and its workers, less what it spends ingesting meanwhile) as a share of
  a core at a 5 s interval. The exposition's families are counted too: what each costs in samples and
  bytes.
- **In this process**, 10k and 100k series over real HTTP: the cached renderer in both formats (robots
  republishing, or every robot changed between scrapes) against a naive `Gauge.labels(...).set()`
  exporter on prometheus-client's own server.
"""

from __future__ import annotations

import argparse
import contextlib
import gzip
import http.server
import os
import re
import signal
import statistics
import subprocess
import tempfile
import threading
import time
import urllib.request
from collections import Counter as Tally
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from prometheus_client import CollectorRegistry, Counter, Gauge, start_http_server

from bench.common import Row, busy_interpreter, emit, tree_cpu_seconds
from overseer.fleet.exposition import FleetExposition
from overseer.fleet.local import LocalFleet
from overseer.messages import DiagnosticArray
from overseer.model import FleetLimits, FleetModel
from overseer.serve.assembler import ExpositionAssembler
from overseer.serve.exposition_formats import TEXT
from overseer.serve.http import OverseerServer
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components
from testbed.ports import free_port, fresh_domain_id
from testbed.processes import running_exporter, running_simulator, wait_for
from testbed.prometheus import running_prometheus

LEAVES = 50
TARGET_MS = 250
FLOOR_RATIO = 1.5  # Prometheus's scrape of the exporter, against its scrape of the same bytes served static
OPENMETRICS_RATIO = 1.3  # OpenMetrics against the text format, same run
BUSY_RATIO = 3.0  # a scrape beside a thread that keeps the interpreter busy (the ingest), against alone
CPU_SHARE_TARGET = 5.0  # % of a core for a scrape every 5 s
INTERVAL_SECONDS = 5
# What Debian's Prometheus (2.42) sends; tests/serve/test_scrape_negotiation.py holds it to the real one.
PROMETHEUS_ACCEPT = (
    "application/openmetrics-text;version=1.0.0,application/openmetrics-text;version=0.0.1;q=0.75,"
    "text/plain;version=0.0.4;q=0.5,*/*;q=0.1"
)
TEXT_ACCEPT = "text/plain;version=0.0.4"


def curl_once(url: str, accept: str, use_gzip: bool) -> tuple[float, int]:
    """One GET `url` by curl (body received, not decompressed): its time in ms and the body's size."""
    encoding = "gzip" if use_gzip else "identity"
    command = ["curl", "-sS", "-o", "/dev/null", "-w", "%{time_total} %{size_download}"]
    command += ["-H", f"Accept: {accept}", "-H", f"Accept-Encoding: {encoding}", url]
    output = subprocess.run(command, capture_output=True, text=True, check=True, timeout=120).stdout.split()
    return float(output[0]) * 1000, int(output[1])


def curl(
    url: str,
    accepts: tuple[str, ...],
    use_gzip: bool,
    repeats: int = 7,
    between: Callable[[], None] | None = None,
) -> list[tuple[float, int]]:
    """Median time (ms) and body size of GET `url` with each of `accepts`, taking turns request by request."""
    timings: list[list[float]] = [[] for _ in accepts]
    sizes = [0] * len(accepts)
    for _ in range(repeats):
        for index, accept in enumerate(accepts):
            if between is not None:
                between()
            elapsed, sizes[index] = curl_once(url, accept, use_gzip)
            timings[index].append(elapsed)
    return [(statistics.median(times), size) for times, size in zip(timings, sizes, strict=True)]


class _StaticExposition(http.server.BaseHTTPRequestHandler):
    """Answers every GET with the same bytes (gzipped ahead of time when asked): the floor."""

    protocol_version = "HTTP/1.1"
    body = b""
    compressed = b""
    content_type = ""

    def do_GET(self) -> None:
        compressed = "gzip" in self.headers.get("Accept-Encoding", "")
        body = self.compressed if compressed else self.body
        self.send_response(200)
        self.send_header("Content-Type", self.content_type)
        self.send_header("Content-Length", str(len(body)))
        if compressed:
            self.send_header("Content-Encoding", "gzip")
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: object) -> None:
        return


class _QuietServer(http.server.ThreadingHTTPServer):
    """A threading server that does not print a traceback when a scraper hangs up (as Prometheus does)."""

    def handle_error(self, request: Any, client_address: Any) -> None:
        return


@contextlib.contextmanager
def static_server(body: bytes, content_type: str, compressed: bytes | None = None) -> Iterator[str]:
    """Serve `body` at every path on loopback (gzipped: `compressed`, or gzip's); yields the host:port."""
    if compressed is None:
        compressed = gzip.compress(body, compresslevel=1)
    handler = type(
        "Floor", (_StaticExposition,), {"body": body, "compressed": compressed, "content_type": content_type}
    )
    server = _QuietServer(("127.0.0.1", free_port()), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield f"127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


def fetch(url: str, accept: str, encoding: str = "identity") -> tuple[bytes, str]:
    """The body (as sent: gzipped when `encoding` asks it) and Content-Type of GET `url` with `accept`."""
    request = urllib.request.Request(url, headers={"Accept": accept, "Accept-Encoding": encoding})
    with urllib.request.urlopen(request, timeout=120) as response:
        return bytes(response.read()), str(response.headers["Content-Type"])


def scrape_durations(prometheus: Any, job: str, seconds: float) -> list[float]:
    """Prometheus's own scrape_duration_seconds of `job` over the last `seconds`, one a scrape."""
    return scraped_values(prometheus, f'scrape_duration_seconds{{job="{job}"}}', seconds)


def scraped_values(prometheus: Any, selector: str, seconds: float) -> list[float]:
    """Every sample `selector`'s series hold from the last `seconds` (one a scrape, every target's), sorted.

    Read raw (a range selector at one instant), so that Prometheus and a store such as VictoriaMetrics,
    which look back differently between the steps of a range query, give the same samples.
    """
    series = prometheus.query(f"{selector}[{max(1, round(seconds))}s]")
    return sorted(float(value) for one in series for _, value in one["values"])


def family_sizes(body: bytes) -> dict[str, tuple[int, int]]:
    """Samples and bytes of each family of an exposition, by the family's name."""
    samples: Tally[str] = Tally()
    sizes: Tally[str] = Tally()
    family = ""
    for line in body.splitlines(keepends=True):
        if line.startswith((b"# HELP ", b"# TYPE ")):
            family = line.split()[2].decode()
        if not line.startswith(b"#"):
            samples[family] += 1
        sizes[family] += len(line)
    return {name: (samples[name], sizes[name]) for name in sizes}


def measure_prometheus(robots: int, components: int, workers: int, seconds: float) -> list[Row]:
    """Prometheus scraping an exporter of `robots` x `components` over DDS, and the same bytes static."""
    label = f"{robots} robots x {components}, {workers} worker{'s' if workers > 1 else ''}"
    domain = fresh_domain_id()
    with (
        tempfile.TemporaryDirectory() as tmp,
        running_simulator(Path(tmp), domain, f"--robots={robots}", f"--components={components}"),
        running_exporter(Path(tmp), domain, f"--ingest.workers={workers}", "--log.level=warning") as exporter,
    ):
        url = exporter.url + "/metrics"

        def every_robot_up() -> bool:
            body, _ = fetch(url, TEXT_ACCEPT)
            up = re.findall(rb"^ros_diagnostics_robot_up\{.*\} (\S+)$", body, re.MULTILINE)
            return len(up) == robots and all(value == b"1.0" for value in up)

        wait_for(every_robot_up, 600, interval=2, message="every robot up")
        pieces, content_type = fetch(url, PROMETHEUS_ACCEPT, "gzip")
        body = gzip.decompress(pieces)
        target = exporter.url.removeprefix("http://")
        with (
            static_server(body, content_type) as floor,
            static_server(body, content_type, pieces) as floor_pieces,
        ):
            jobs = [("overseer", target), ("floor", floor), ("floor_pieces", floor_pieces)]
            config = {
                "global": {
                    "scrape_interval": f"{INTERVAL_SECONDS}s",
                    "scrape_timeout": f"{INTERVAL_SECONDS}s",
                },
                "scrape_configs": [
                    {"job_name": job, "static_configs": [{"targets": [t]}]} for job, t in jobs
                ],
            }
            with running_prometheus(Path(tmp), config) as prometheus:
                time.sleep(seconds)
                ours = scrape_durations(prometheus, "overseer", seconds)
                floors = scrape_durations(prometheus, "floor", seconds)
                pieces_floors = scrape_durations(prometheus, "floor_pieces", seconds)
                samples = prometheus.query('scrape_samples_scraped{job="overseer"}')
        scraped = float(samples[0]["value"][1]) if samples else 0.0
        curls = {
            use_gzip: curl(url, (TEXT_ACCEPT, PROMETHEUS_ACCEPT), use_gzip) for use_gzip in (False, True)
        }
        cpu_per_scrape = exporter_cpu_per_scrape(exporter.process.pid, url)
    ours_median, floor_median = statistics.median(ours), statistics.median(floors)
    ratio = ours_median / floor_median
    pieces_median = statistics.median(pieces_floors)
    rows = [
        Row("scrape", f"{label}: samples a scrape", scraped, "samples"),
        Row("scrape", f"{label}: exposition (OpenMetrics, plain)", len(body) / 1e6, "MB"),
        Row(
            "scrape",
            f"{label}: Prometheus scrape_duration_seconds, exporter (median)",
            ours_median * 1000,
            "ms",
        ),
        Row("scrape", f"{label}: Prometheus scrape_duration_seconds, exporter (max)", max(ours) * 1000, "ms"),
        Row(
            "scrape",
            f"{label}: Prometheus scrape_duration_seconds, floor (median)",
            floor_median * 1000,
            "ms",
        ),
        Row(
            "scrape",
            f"{label}: Prometheus, exporter / floor",
            ratio,
            "x",
            f"<= {FLOOR_RATIO}",
            ratio <= FLOOR_RATIO,
        ),
        Row(
            "scrape",
            f"{label}: Prometheus scrape_duration_seconds, floor gzipped as the exporter does (median)",
            pieces_median * 1000,
            "ms",
        ),
        Row(
            "scrape",
            f"{label}: Prometheus, the same text in the exporter's gzip pieces / gzipped whole",
            pieces_median / floor_median,
            "x",
        ),
        Row("scrape", f"{label}: scrapes measured, exporter", len(ours), "scrapes"),
        Row("scrape", f"{label}: scrapes measured, floor", len(floors), "scrapes"),
        Row(
            "scrape",
            f"{label}: scrapes measured, floor in the exporter's pieces",
            len(pieces_floors),
            "scrapes",
        ),
    ]
    for use_gzip in (False, True):
        kind = "gzip" if use_gzip else "plain"
        (text_ms, text_size), (openmetrics_ms, _) = curls[use_gzip]
        rows += [
            Row("scrape", f"{label}: curl, text format, {kind}", text_ms, "ms"),
            Row("scrape", f"{label}: curl, OpenMetrics (Prometheus's Accept), {kind}", openmetrics_ms, "ms"),
            Row(
                "scrape",
                f"{label}: curl, OpenMetrics / text, {kind}",
                openmetrics_ms / text_ms,
                "x",
                f"<= {OPENMETRICS_RATIO}",
                openmetrics_ms / text_ms <= OPENMETRICS_RATIO,
            ),
            Row("scrape", f"{label}: body, text format, {kind}", text_size / 1e6, "MB"),
        ]
    share = cpu_per_scrape / INTERVAL_SECONDS * 100
    rows += [
        Row(
            "scrape",
            f"{label}: exporter CPU per scrape (Prometheus's Accept, gzip)",
            cpu_per_scrape * 1000,
            "ms",
        ),
        Row(
            "scrape",
            f"{label}: exporter CPU scraped every {INTERVAL_SECONDS} s",
            share,
            "% of a core",
            f"<= {CPU_SHARE_TARGET:g}",
            share <= CPU_SHARE_TARGET,
        ),
    ]
    if workers == 1:
        for family, (count, size) in family_sizes(body).items():
            if count:
                rows.append(Row("scrape", f"{label}: family {family}", count, "samples"))
                rows.append(Row("scrape", f"{label}: family {family}, bytes", size / 1e6, "MB"))
    return rows


def exporter_cpu_per_scrape(pid: int, url: str, scrapes: int = 8) -> float:
    """CPU seconds the exporter (and its workers) spend on one scrape, beyond what it spends meanwhile."""
    idle_started, idle_cpu = time.monotonic(), tree_cpu_seconds(pid)
    time.sleep(10)
    idle_rate = (tree_cpu_seconds(pid) - idle_cpu) / (time.monotonic() - idle_started)
    started, cpu = time.monotonic(), tree_cpu_seconds(pid)
    for _ in range(scrapes):
        curl_once(url, PROMETHEUS_ACCEPT, True)
    spent = tree_cpu_seconds(pid) - cpu - idle_rate * (time.monotonic() - started)
    return max(spent, 0.0) / scrapes


def statuses_for(robot: int, version: int) -> DiagnosticArray:
    leaves = leaf_components(LEAVES)
    statuses = aggregated_statuses(leaves, initial_levels(leaves, 2, 2), set())
    voltage = f"{11 + robot / 1000 + version / 1e5:.5f}"
    varied = [
        s._replace(values=tuple((k, voltage if k == "voltage" else v) for k, v in s.values)) for s in statuses
    ]
    return DiagnosticArray(0, 0, "", tuple(varied))


def naive_exporter(model: FleetModel) -> tuple[Callable[[], None], str]:
    """prometheus-client's own server with `Gauge.labels(...).set()` for every series; (stop, url)."""
    registry = CollectorRegistry()
    labels = ["robot", "component", "hardware_id"]
    level = Gauge("ros_diagnostics_level", "level", labels, registry=registry)
    changes = Counter("ros_diagnostics_level_changes", "changes", labels, registry=registry)
    value = Gauge("ros_diagnostics_value", "value", [*labels, "key"], registry=registry)
    for robot in model.snapshot().robots:
        for component in robot.components.values():
            identity = (robot.name, component.name, component.hardware_id)
            level.labels(*identity).set(float(component.level))
            changes.labels(*identity).inc(0)
            for key, text in component.values:
                with contextlib.suppress(ValueError):
                    value.labels(*identity, key).set(float(text))
    server, _ = start_http_server(0, addr="127.0.0.1", registry=registry)
    return server.shutdown, f"http://127.0.0.1:{server.server_address[1]}/metrics"


def measure_in_process(series_wanted: int) -> list[Row]:
    """The cached renderer over HTTP in this process, both formats, against the naive exporter."""
    model = FleetModel(FleetLimits(max_robots=100_000, stale_after=3600, robot_timeout=3600))
    exposition = FleetExposition(model, re.compile(".*"))
    assembler = ExpositionAssembler(["dds"])
    model.apply("robot0", statuses_for(0, 0), "dds")
    per_robot = assembler.assemble([exposition.render_part()]).count(b"\n") - 34
    robots = 1
    while robots * per_robot < series_wanted:
        model.apply(f"robot{robots}", statuses_for(robots, 0), "dds")
        robots += 1
    server = OverseerServer(("127.0.0.1", 0), LocalFleet(model, [], exposition), assembler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    series = assembler.assemble([exposition.render_part()], TEXT).count(b"\n") - 34
    stop_naive, naive_url = naive_exporter(model)
    url = f"{server.url}/metrics"
    names = [r.name for r in model.snapshot().robots]
    version = [0]

    def republish() -> None:
        for name in names:
            model.touch(name, "dds")

    def change() -> None:
        version[0] += 1
        for index, name in enumerate(names):
            model.apply(name, statuses_for(index, version[0]), "dds")

    rows = []
    label = f"{series // 1000}k series"
    for use_gzip in (False, True):
        kind = "gzip" if use_gzip else "plain"
        (ours, size), (openmetrics, _) = curl(url, (TEXT_ACCEPT, PROMETHEUS_ACCEPT), use_gzip, 9, republish)
        [(changing, _)] = curl(url, (TEXT_ACCEPT,), use_gzip, 3, change)
        [(naive, _)] = curl(naive_url, (TEXT_ACCEPT,), use_gzip, 3)
        rows += [
            Row(
                "scrape", f"{label}, {kind}: Overseer, text", ours, "ms", f"<= {TARGET_MS}", ours <= TARGET_MS
            ),
            Row(
                "scrape",
                f"{label}, {kind}: Overseer, OpenMetrics",
                openmetrics,
                "ms",
                f"<= {OPENMETRICS_RATIO} x text",
                openmetrics <= OPENMETRICS_RATIO * ours,
            ),
            Row(
                "scrape",
                f"{label}, {kind}: Overseer, text, every robot changed",
                changing,
                "ms",
                f"<= {TARGET_MS}",
                changing <= TARGET_MS,
            ),
            Row("scrape", f"{label}, {kind}: naive Gauge.labels exporter", naive, "ms"),
            Row("scrape", f"{label}, {kind}: naive / Overseer", naive / ours, "x", ">= 4", naive / ours >= 4),
            Row("scrape", f"{label}, {kind}: body size", size / 1e6, "MB"),
        ]
        with busy_interpreter():
            [(busy, _)] = curl(url, (TEXT_ACCEPT,), use_gzip, 3, change)
        # Below 100k series a scrape is a few ms of work, and the handovers every request makes (accept,
        # read the request, compress, send: up to 5 ms each beside a busy thread) dominate.
        held = series_wanted >= 100_000
        rows += [
            Row(
                "scrape",
                f"{label}, {kind}: Overseer, text, every robot changed, beside a busy thread",
                busy,
                "ms",
            ),
            Row(
                "scrape",
                f"{label}, {kind}: beside a busy thread / alone",
                busy / changing,
                "x",
                f"<= {BUSY_RATIO} (2: a fair share of the interpreter)" if held else "",
                busy / changing <= BUSY_RATIO if held else None,
            ),
        ]
    server.shutdown()
    stop_naive()
    return rows


def main() -> None:
    """Prometheus at 1,000 robots (one worker, then one per core), then the in-process figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--robots", type=int, default=1000)
    parser.add_argument("--components", type=int, default=LEAVES)
    parser.add_argument("--seconds", type=float, default=60, help="how long Prometheus scrapes each exporter")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, max(2, len(os.sched_getaffinity(0)))])
    parser.add_argument("--skip-prometheus", action="store_true", help="only the in-process figures")
    options = parser.parse_args()
    rows: list[Row] = []
    if not options.skip_prometheus:
        for workers in options.workers:
            rows += measure_prometheus(options.robots, options.components, workers, options.seconds)
    rows += measure_in_process(10_000) + measure_in_process(100_000)
    emit(rows)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # stop the servers it started on SIGTERM too
    main()
