"""One exporter under the load generator's fleet: lost updates, CPU per message, memory, /metrics, by size.

`python -m bench.bench_scale --robots 1000,3000 --workers 1,2` runs, for each size and worker count,
one Python Zenoh router, `overseer run --dds.disabled --zenoh.connect ROUTER --ingest.workers W`, and
the load generator (`bench.loadgen`) publishing N robots x 50 components at 1 Hz as rmw_zenoh does,
with the realistic profile (1 % of statuses changing a second, 2 % of robots in trouble) unless
`--profile live`; `--components`, `--rate`, `--change-share`, `--trouble-share`, `--down-share`,
`--down-seconds` and `--seed` shape the fleet as they do `bench.loadgen`'s. The generator waits until
the exporter's subscriptions match every robot, so the ramp-up (every robot's first array) is inside
the window. With `--head-start S` the robots are declared S seconds before they first publish; by
default they publish as soon as they are declared, as a fleet that starts all at once or comes back to
a restarted router, and a router passing 10,000 robots' 20,000 tokens on drops samples while it does.
Beside the fleet, one more robot (`bench.change_probe`) changes a value every second: the time each
change takes to reach the exporter's model, which every scrape renders, gives the p99 of a change's time
to `/metrics` (target <= 1 s). In the window's last seconds, check_ros_diagnostics of one robot is timed
against `python -c pass`.
The first look (every robot's first array read whole, with one event a component) holds up what arrives
meanwhile: how long it took is printed, and the p99 is given over the whole window and after it (the
target's). With `--floor` a subscriber that only counts (`bench.zenoh_counter`, subscribed to the
tokens as the exporter is) hears the same fleet through the same router: what it missed, the router
never delivered to anyone (a second subscriber of the tokens adds to the router's work as a fleet
starts).
Lost updates = messages the generator published minus messages the exporter counted as received (the
probe's taken out); CPU is the exporter's processes' (main and workers) over the window; with
workers, the steady window's CPU is also told apart: the exporter's own process and the busiest worker
(`bench/worker_cpu.py`), and each run of several workers is divided by the nearest run of one worker in
the same invocation (`--workers 1,2,4`, one shard): the whole about 1 time one worker's and the busiest
worker at most 1/N of it if the workers divide the ingest, the whole about N times and the busiest about
once if each did all of it. The generator's own CPU per 1,000 robots is printed beside every figure.
`--transport dds` publishes raw DDS writes on a fresh loopback domain instead, with no router and no
probe (it publishes as rmw_zenoh); with `--dds-shared-topic` every robot writes the absolute
`/diagnostics`, as diagnostic_updater does, the ROS graph naming each writer's node.

With `--prometheus-seconds S` the generator goes on after the window while Debian's Prometheus scrapes
the exporter for S seconds (every `--scrape-interval`, with its own Accept header and gzip) and, in the
same Prometheus, a static server answering the exporter's own bytes: Prometheus's own
`scrape_duration_seconds` of both, their ratio (target <= 1.3x) and the scrapes that failed (with
`--floor-pieces` a third static server answers the same text gzipped in the exporter's pieces); with
`--rules`, then a Prometheus with the shipped default config and rules (scraping every
`--scrape-interval`) gives each rule group's evaluation time as a share of its interval (target <= 10 %,
with the generator's 2 % of robots in trouble), and the rules that cost the most, from /api/v1/rules.
The lost updates then cover the whole run, Prometheus included. With `--prometheus-agent [STORE]` that
Prometheus runs in agent mode and sends what it scrapes (`remote_write`) to a store that answers the
queries (a second Prometheus, or Debian's single-node VictoriaMetrics with `victoria-metrics`): the
layout for a fleet split into `--shards N` exporters (`--shard I/N`, `--workers` each, every figure
theirs together), one store for them all. With `--page`, after the window and while the fleet goes on
publishing, Debian's Chromium loads the status page (the fleet, then one robot: first render, target
<= 1 s) and `/api/v1/robots` and the newest page of `/api/v1/events` are timed.
"""

from __future__ import annotations

import argparse
import contextlib
import gzip
import re
import statistics
import tempfile
import time
import urllib.request
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, NamedTuple, TypeVar

from bench.bench_alert_rules import PROFILES, alert_counts, observe, target_rows
from bench.bench_check import (
    CHECK,
    TARGET_RATIO,
    cached_environment,
    require_judged,
    shebang_interpreter,
    wall_times,
)
from bench.bench_scrape import PROMETHEUS_ACCEPT, fetch, scrape_durations, scraped_values, static_server
from bench.bench_status_page import first_render_ms, get_ms
from bench.change_probe import PROBE_ROBOT, ChangeProbe
from bench.common import (
    Row,
    cpu_seconds,
    emit,
    forest,
    highest_tree_resident,
    series_total,
    tree_cpu_seconds,
    tree_proportional_bytes,
    tree_resident_bytes,
)
from bench.loadgen import (
    add_shape_arguments,
    check_head_start,
    check_shape,
    running_loadgen,
    shape_arguments,
    shape_of,
)
from bench.loadgen_payloads import REALISTIC, FleetShape
from bench.loadgen_wire import DDS, TRANSPORTS, ZENOH
from bench.scale_icinga2 import icinga2_receiving
from bench.worker_cpu import STEADY_CPU_A_MESSAGE, ProcessesCpu, compared_with_one_worker
from bench.zenoh_counter import CounterProcess, running_counter
from overseer.config.ingest import MAX_INGEST_WORKERS
from overseer.model.shard import Shard
from overseer.model.state import FleetLimits
from testbed.browser import headless_chromium
from testbed.ports import fresh_domain_id
from testbed.processes import Exporter, RunningProcess, running_exporter
from testbed.prometheus import (
    Prometheus,
    running_agent,
    running_prometheus,
    running_store,
    running_victoria_metrics,
    shipped_config,
)
from testbed.zenoh import endpoint, exporter_args, running_router_process

DEFAULT_MAX_ROBOTS = FleetLimits().max_robots
SETTLE_SECONDS = 4.0  # after the generator stops, for the last samples to be counted
FLOOR_RATIO = 1.3  # Prometheus's scrape of the exporter against its scrape of the same bytes served static
RULE_SHARE_SHOWN = 0.5  # % of the group's interval: the rules that cost at least this get a row
CHECK_RUNS = 10
CHECK_SECONDS = 15  # the check is timed in the window's last seconds, while the fleet publishes
MEMORY_TARGET = 1000  # bytes a component, the exporter's processes together (issue 32)
PAGE_SECONDS = 90  # the generator publishes this much longer while Chromium loads the status page
PAGE_LOADS = 3
PROMETHEUS_SETUP_SECONDS = 300  # the generator's margin for the body's fetch and Prometheus's start
CHECKED_ROBOT = "robot1"  # the check, the page and the API read this robot of the fleet
MAX_SHARDS = 8
VICTORIA_METRICS = "victoria-metrics"
STORES = ("prometheus", VICTORIA_METRICS)  # what a Prometheus agent can send its samples to, here

_Shard = TypeVar("_Shard")


class Counts(NamedTuple):
    """What the exporter counted, from one `/metrics`."""

    received: float  # messages over the transport
    lost: float  # samples its robots published that it says it never heard (Zenoh's sequence numbers)
    dropped: float  # messages it heard and dropped, or cut: its queue full, a cap, an invalid level
    events_written: float
    events_dropped: float
    renders_ahead: float  # of the series, shortly before a scrape expected (metrics.render_ahead)
    render_ahead_passes: float  # renders again after them, until the scrape began
    render_ahead_skipped: float  # expected scrapes not rendered ahead of, after futile passes
    render_ahead_seconds: float  # how long the last took
    over_cap: float  # statuses dropped because their robot was beyond fleet.max_robots


def together(counts: Sequence[Counts]) -> Counts:
    """Several shards' counts as one exporter's: summed, but the last render ahead the longest."""
    summed = Counts(*(sum(values) for values in zip(*counts, strict=True)))
    return summed._replace(render_ahead_seconds=max(count.render_ahead_seconds for count in counts))


def shard_of(exporters: Sequence[_Shard], robot: str) -> _Shard:
    """The exporter, of shards `0/N` to `N-1/N` in that order, that follows `robot`."""
    return next(e for index, e in enumerate(exporters) if Shard(index, len(exporters)).owns(robot))


@contextlib.contextmanager
def running_shards(directory: Path, wires: Wiring, shards: int, *args: str) -> Iterator[list[Exporter]]:
    """`shards` exporters wired to the fleet, each `--shard I/N` (one: no flag), with `args`."""
    with contextlib.ExitStack() as stack:
        yield [
            stack.enter_context(
                running_exporter(
                    directory,
                    wires.domain,
                    *wires.exporter_args,
                    *([f"--shard={index}/{shards}"] if shards > 1 else []),
                    *args,
                )
            )
            for index in range(shards)
        ]


def metrics_text(url: str) -> str:
    """`/metrics` as text, read as Prometheus reads it (`scrape`).

    A plain-text read of 10,000 robots would make the exporter inflate every robot's compressed lines,
    170 MB, which its memory, measured next, would count.
    """
    return scrape_text(url)[0].decode()


def followed_robots(text: str) -> set[str]:
    """The robots an exporter's `/metrics` text lists (up or down): those it follows."""
    return set(re.findall(r'^ros_diagnostics_robot_up\{robot="((?:[^"\\]|\\.)*)"\} ', text, re.MULTILINE))


def counted(text: str, transport: str) -> Counts:
    """Messages received, lost and dropped over `transport`, events, renders ahead, robots beyond the cap."""

    def total(pattern: str) -> float:
        return series_total(text, pattern)

    def messages(result: str) -> float:
        return total(rf'overseer_messages_total\{{result="{result}",transport="{transport}"\}}')

    return Counts(
        messages("received"),
        messages("lost"),
        messages("dropped"),
        total("overseer_events_written_total"),
        total(r"overseer_events_dropped_total\{reason=\"[a-z_]+\"\}"),
        total(r'overseer_exposition_renders_ahead_total\{result="done"\}'),
        total("overseer_exposition_render_ahead_passes_total"),
        total(r'overseer_exposition_renders_ahead_total\{result="skipped"\}'),
        total("overseer_exposition_render_ahead_seconds"),
        total(r'overseer_statuses_dropped_total\{reason="robot_limit"\}'),
    )


def scrape(url: str) -> tuple[float, int]:
    """Seconds of one `/metrics` read as Prometheus asks for it (text format, gzip), and the text's bytes."""
    text, seconds = scrape_text(url)
    return seconds, len(text)


def scrape_text(url: str) -> tuple[bytes, float]:
    """`/metrics` read as Prometheus asks for it (text format, gzip), as text, and the seconds it took."""
    headers = {"Accept": "text/plain;version=0.0.4", "Accept-Encoding": "gzip"}
    request = urllib.request.Request(url + "/metrics", headers=headers)
    started = time.perf_counter()
    with urllib.request.urlopen(request, timeout=300) as response:
        body = response.read()
        gzipped = response.headers.get("Content-Encoding") == "gzip"
    seconds = time.perf_counter() - started
    return gzip.decompress(body) if gzipped else body, seconds


@dataclass(frozen=True)
class Wiring:
    """How the exporter and the generator reach each other over one transport, and the router if any."""

    exporter_args: tuple[str, ...]
    loadgen_args: tuple[str, ...]
    domain: int | None = None  # the DDS domain
    router: RunningProcess | None = None  # the Zenoh router
    zenoh_endpoint: str | None = None

    def router_cpu(self) -> float:
        """The router's CPU seconds so far (0 without one)."""
        return cpu_seconds(self.router.process.pid) if self.router else 0.0

    def probe(
        self, exporter_url: str, components: int
    ) -> contextlib.AbstractContextManager[ChangeProbe | None]:
        """The change probe over Zenoh; none over DDS (the probe publishes as rmw_zenoh does)."""
        if self.zenoh_endpoint is None:
            return contextlib.nullcontext()
        return ChangeProbe(exporter_url, self.zenoh_endpoint, components)


@contextlib.contextmanager
def wiring(transport: str, directory: Path, shared_topic: bool = False) -> Iterator[Wiring]:
    """A Zenoh router for both sides, or a fresh DDS domain on loopback (robots on `/diagnostics`: shared)."""
    if transport == DDS:
        domain = fresh_domain_id()
        shared = ("--dds-shared-topic",) if shared_topic else ()
        yield Wiring((), ("--transport=dds", f"--domain={domain}", *shared), domain)  # Zenoh off unless asked
        return
    with running_router_process(directory) as (port, router):
        loadgen_args = (f"--zenoh.connect={endpoint(port)}", "--zenoh.listen=tcp/127.0.0.1:0")
        yield Wiring(exporter_args(port), loadgen_args, None, router, endpoint(port))


@contextlib.contextmanager
def floor_counter(wires: Wiring, directory: Path, wanted: bool) -> Iterator[CounterProcess | None]:
    """The counting subscriber beside the exporter, when `wanted` and the fleet is on Zenoh."""
    if not wanted or wires.zenoh_endpoint is None:
        yield None
        return
    with running_counter(wires.zenoh_endpoint, directory, "0/**", tokens=True) as counter:
        yield counter


class Scraping(NamedTuple):
    """The servers of one layout: the one answering queries, every one (for CPU and memory), the agent."""

    queried: Prometheus
    servers: list[Prometheus]
    agent: Prometheus | None


@contextlib.contextmanager
def scraping_prometheus(directory: Path, config: dict[str, Any], store: str | None) -> Iterator[Scraping]:
    """The servers that scrape as `config` says, and hold what they scraped.

    With a `store` (one of STORES), Prometheus scrapes in agent mode and sends every sample
    (`remote_write`) to that store, which answers the queries.
    """
    if store not in (None, *STORES):
        raise ValueError(f"store: one of {', '.join(STORES)}, got {store!r}")
    if store is None:
        with running_prometheus(directory, config) as prometheus:
            yield Scraping(prometheus, [prometheus], None)
        return
    starting = running_victoria_metrics if store == VICTORIA_METRICS else running_store
    with starting(directory) as receiver:
        sending = {**config, "remote_write": [{"url": receiver.url + "/api/v1/write"}]}
        with running_agent(directory, sending) as agent:
            yield Scraping(receiver, [agent, receiver], agent)


def wait_until_sent(agent: Prometheus, timeout: float = 120.0) -> None:
    """Wait until `agent` has sent its store every sample it had taken in when called (or `timeout`)."""

    def newest(gauge: str) -> float:
        with urllib.request.urlopen(agent.url + "/metrics", timeout=10) as response:
            text = response.read().decode()
        values = re.findall(rf"^{gauge}(?:{{[^}}]*}})? (\S+)$", text, re.MULTILINE)
        return max((float(value) for value in values), default=0.0)

    taken_in = newest("prometheus_remote_storage_highest_timestamp_in_seconds")
    deadline = time.monotonic() + timeout
    while newest("prometheus_remote_storage_queue_highest_sent_timestamp_seconds") < taken_in:
        if time.monotonic() > deadline:
            raise TimeoutError(f"the agent did not send its samples of {taken_in} within {timeout} s")
        time.sleep(1.0)


def scrape_against_floor(
    exporters: Sequence[Exporter],
    components: int,
    directory: Path,
    seconds: float,
    interval: int,
    pieces: bool = False,
    store: str | None = None,
) -> list[Row]:
    """Prometheus scraping the exporters and a static copy of each one's bytes for `seconds`: its durations.

    Meanwhile the exporters' memory (their `components` following) is read every second: a scrape takes
    memory of its own, which the figures read before and after Prometheus would not show.
    With `pieces`, a third static server a shard answers the same text gzipped as the exporter does (its
    robots' deflated pieces end to end, where the floor's is one gzip stream): what the pieces cost
    Prometheus. With a `store`, Prometheus scrapes in agent mode into that store (above).
    """
    answers = [fetch(exporter.url + "/metrics", PROMETHEUS_ACCEPT, "gzip") for exporter in exporters]
    bodies = [(gzip.decompress(gzipped), gzipped, content_type) for gzipped, content_type in answers]
    with contextlib.ExitStack() as servers:
        floors = [servers.enter_context(static_server(body, kind)) for body, _, kind in bodies]
        floors_in_pieces = [
            servers.enter_context(static_server(body, kind, gzipped))
            for body, gzipped, kind in (bodies if pieces else [])
        ]
        jobs = [("overseer", [exporter.url.removeprefix("http://") for exporter in exporters])]
        jobs += [("floor", floors)] + ([("floor_pieces", floors_in_pieces)] if pieces else [])
        config = {
            "global": {"scrape_interval": f"{interval}s", "scrape_timeout": f"{interval}s"},
            "scrape_configs": [
                {"job_name": job, "static_configs": [{"targets": targets}]} for job, targets in jobs
            ],
        }
        with scraping_prometheus(directory, config, store) as (prometheus, scrapers, agent):
            pids = [exporter.process.pid for exporter in exporters]
            scraped_rss = highest_tree_resident(pids, time.monotonic() + seconds)
            if agent is not None:  # the store holds a scrape once the agent has sent it
                wait_until_sent(agent)
            ours = scrape_durations(prometheus, "overseer", seconds)
            floors_seconds = scrape_durations(prometheus, "floor", seconds)
            pieces_floors = scrape_durations(prometheus, "floor_pieces", seconds) if pieces else []
            # Once the exporter has learned Prometheus's interval (metrics.render_ahead: three scrapes).
            learned = seconds - 3 * interval
            ours_learned = scrape_durations(prometheus, "overseer", learned) if learned > 0 else []
            floors_learned = scrape_durations(prometheus, "floor", learned) if learned > 0 else []
            # The exporter's own wait for its series before the first byte, stored at each scrape.
            render_seconds = 'overseer_exposition_last_render_seconds{job="overseer"}'
            renders_learned = scraped_values(prometheus, render_seconds, learned) if learned > 0 else []
            window = f"{int(seconds)}s"
            attempts = prometheus.query(f'sum(count_over_time(up{{job="overseer"}}[{window}]))')
            succeeded = prometheus.query(f'sum(sum_over_time(up{{job="overseer"}}[{window}]))')
            samples = prometheus.query('sum(scrape_samples_scraped{job="overseer"})')
            targets = prometheus.query('count(up{job="overseer"})')
            prometheus_cpu = sum(cpu_seconds(server.process.pid) for server in scrapers) / seconds * 100
            prometheus_memory = sum(tree_resident_bytes(server.process.pid) for server in scrapers)
    failed = float(attempts[0]["value"][1]) - float(succeeded[0]["value"][1]) if attempts else 0.0
    ours_median = statistics.median(ours) if ours else float("nan")
    floor_median = statistics.median(floors_seconds) if floors_seconds else float("nan")
    ratio = ours_median / floor_median
    return [
        Row(
            "scale",
            "Prometheus: samples a scrape",
            float(samples[0]["value"][1]) if samples else 0,
            "samples",
        ),
        Row("scale", "Prometheus: exporters scraped", float(targets[0]["value"][1]) if targets else 0, ""),
        Row(
            "scale",
            "Prometheus: exposition (its Accept, plain)",
            sum(len(body) for body, _, _ in bodies) / 1e6,
            "MB",
        ),
        Row("scale", "Prometheus: scrape_duration_seconds, exporter (median)", ours_median, "s"),
        Row("scale", "Prometheus: scrape_duration_seconds, exporter (max)", max(ours, default=0.0), "s"),
        Row("scale", "Prometheus: scrape_duration_seconds, floor (median)", floor_median, "s"),
        Row("scale", "Prometheus: exporter / floor", ratio, "x", f"<= {FLOOR_RATIO}", ratio <= FLOOR_RATIO),
        *(
            [
                Row(
                    "scale",
                    "Prometheus: floor in the exporter's gzip pieces / floor, medians",
                    statistics.median(pieces_floors) / floor_median,
                    "x",
                ),
                Row(
                    "scale",
                    "Prometheus: exporter / floor in its gzip pieces, medians",
                    ours_median / statistics.median(pieces_floors),
                    "x",
                ),
            ]
            if pieces_floors
            else []
        ),
        *(
            [
                Row(
                    "scale",
                    "Prometheus: exporter / floor, medians after three intervals",
                    statistics.median(ours_learned) / statistics.median(floors_learned),
                    "x",
                ),
                Row(
                    "scale",
                    "Prometheus: scrapes after three intervals, exporter",
                    len(ours_learned),
                    "scrapes",
                ),
                Row(
                    "scale",
                    "Prometheus: of which the exporter rendered before its first byte, median",
                    statistics.median(renders_learned) if renders_learned else float("nan"),
                    "s",
                ),
            ]
            if ours_learned and floors_learned
            else []
        ),
        Row("scale", "Prometheus: scrapes measured, exporter / floor", len(ours), f"/ {len(floors_seconds)}"),
        Row("scale", "Prometheus: exporter scrapes failed", failed, "scrapes", "0", failed == 0),
        Row(
            "scale",
            "Prometheus: the exporter's memory a component, the most while scraped (read every second)",
            scraped_rss / components,
            "bytes",
            f"<= {MEMORY_TARGET}",
            scraped_rss / components <= MEMORY_TARGET,
        ),
        Row("scale", "Prometheus: its CPU since it started (every process)", prometheus_cpu, "% of a core"),
        Row("scale", "Prometheus: its resident memory (every process)", prometheus_memory / 1e6, "MB"),
    ]


def check_rows(url: str, robot: str, runs: int = CHECK_RUNS) -> list[Row]:
    """check_ros_diagnostics of one robot against the exporter now, beside `python -c pass` (target <= 2x)."""
    commands = {
        "python": [shebang_interpreter(CHECK), "-c", "pass"],
        "check": [str(CHECK), "--url", url, "-r", robot],
    }
    require_judged(commands["check"], robot)
    with tempfile.TemporaryDirectory(prefix="bench-pycache-") as cache:
        times = wall_times(commands, runs, cached_environment(cache))
    check, python = statistics.median(times["check"]), statistics.median(times["python"])
    return [
        Row("scale", f"check_ros_diagnostics -r {robot}, median", check * 1000, "ms"),
        Row(
            "scale",
            "check_ros_diagnostics / python -c pass",
            check / python,
            "x",
            f"<= {TARGET_RATIO:g}",
            check / python <= TARGET_RATIO,
        ),
    ]


def page_rows(url: str, robot: str) -> list[Row]:
    """The status page's first render in Chromium, the JSON it reads and the event history, under traffic."""
    with headless_chromium() as browser:
        fleet = first_render_ms(browser, url + "/", "fleet", PAGE_LOADS)
        one = first_render_ms(browser, f"{url}/?robot={robot}", "robot", PAGE_LOADS)
    robots_ms, robots_bytes = get_ms(url + "/api/v1/robots", PAGE_LOADS)
    events_ms, _ = get_ms(url + "/api/v1/events?limit=100", PAGE_LOADS)
    return [
        Row("scale", "status page first render, fleet view", fleet, "ms", "<= 1000", fleet <= 1000),
        Row("scale", "status page first render, one robot", one, "ms", "<= 1000", one <= 1000),
        Row("scale", f"GET /api/v1/robots ({robots_bytes / 1e6:.1f} MB)", robots_ms, "ms"),
        Row("scale", "GET /api/v1/events?limit=100 (the newest events)", events_ms, "ms"),
    ]


def rule_times(
    prometheus: Prometheus, readings: int = 5, apart: float = 15.0
) -> dict[tuple[str, str], float]:
    """Each rule's median evaluation time over `readings` of /api/v1/rules, in % of its group's interval."""
    times: dict[tuple[str, str], list[float]] = {}
    intervals: dict[str, float] = {}
    for reading in range(readings):
        if reading:
            time.sleep(apart)
        for group in prometheus.api("rules")["groups"]:
            intervals[group["name"]] = float(group["interval"])
            for rule in group["rules"]:
                key = (group["name"], rule["name"])
                times.setdefault(key, []).append(float(rule["evaluationTime"]))
    return {key: 100 * statistics.median(values) / intervals[key[0]] for key, values in times.items()}


def shipped_rules_rows(
    exporter_urls: Sequence[str], directory: Path, seconds: float, interval: int
) -> list[Row]:
    """The default profile's shipped config and rules, scraping every `interval`: each group's share."""
    config = shipped_config(PROFILES["default"], exporter_urls)
    config["global"].update(scrape_interval=f"{interval}s", scrape_timeout=f"{interval}s")
    with running_prometheus(directory, config) as prometheus:
        time.sleep(2 * interval)  # the first scrapes in: the rules then read the whole fleet
        phase = observe(prometheus, seconds)
        counts = alert_counts(prometheus)
        rules = rule_times(prometheus)
    return [
        *target_rows("shipped rules", phase),
        *(
            Row("scale", f"shipped rules: {group}, {rule}: median", share, "% of the group's interval")
            for (group, rule), share in sorted(rules.items(), key=lambda item: -item[1])
            if share >= RULE_SHARE_SHOWN
        ),
        Row(
            "scale",
            "shipped rules: alerts firing / pending",
            counts.get("firing", 0),
            f"/ {counts.get('pending', 0)}",
        ),
    ]


def transport_label(transport: str, shared_topic: bool) -> str:
    """The transport as the rows name it: over DDS, whether every robot writes the one `/diagnostics`."""
    return f"{transport}, every robot on /diagnostics" if shared_topic else transport


def setup_label(shards: int, store: str | None, head_start: float, exporter_options: Sequence[str]) -> str:
    """What a row's name says after the worker count: shards, the agent's store, a head start, options."""
    label = f" in each of {shards} shards" if shards > 1 else ""
    label += f", Prometheus in agent mode into {store}" if store else ""
    label += f", declared {head_start:g} s before publishing" if head_start else ""
    return label + "".join(f", {option}" for option in exporter_options)


def fleet_label(shape: FleetShape, rate: float) -> str:
    """The fleet in a row's name: its size and rate, its profile, and what differs from the defaults."""
    label = f"{shape.robots} robots x {shape.components}"
    label += "" if rate == 1 else f" at {rate:g} Hz"
    label += f", {shape.profile}"
    default = FleetShape(shape.robots, shape.components, shape.profile)
    if shape.profile == REALISTIC and shape.change_share != default.change_share:
        label += f", {shape.change_share:.2%} of statuses changing a second"
    if shape.trouble_share != default.trouble_share:
        label += f", {shape.trouble_share:.2%} of robots in trouble"
    if shape.down_share != default.down_share:
        label += f", {shape.down_share:.2%} going down a minute for {shape.down_seconds:g} s"
    return label + ("" if shape.seed == default.seed else f", seed {shape.seed}")


def run(
    shape: FleetShape,
    workers: int,
    seconds: float,
    prometheus_seconds: float = 0,
    interval: int = 30,
    exporter_options: tuple[str, ...] = (),
    rules: bool = False,
    transport: str = ZENOH,
    rate: float = 1.0,
    floor: bool = False,
    page: bool = False,
    head_start: float = 0.0,
    floor_pieces: bool = False,
    shards: int = 1,
    store: str | None = None,
    icinga2_interval: float | None = None,
    shared_topic: bool = False,
) -> list[Row]:
    """Publish `shape`'s fleet at `rate` for `seconds` into an exporter with `workers` ingest workers.

    `floor`: a subscriber that only counts (`bench.zenoh_counter`, the exporter's token subscription
    too) hears the same fleet through the same router in the same run: the samples the router itself
    does not deliver. `page`: after the window, while the fleet goes on publishing, Chromium loads the
    status page and the JSON API and event history are read. `head_start`: the robots are declared that
    many seconds before they publish (a router takes seconds to pass a large fleet's tokens on).
    `floor_pieces`: Prometheus also scrapes the floor's text gzipped as the exporter gzips it.
    `shards`: that many exporters (`--shard I/N`, `workers` each) share the fleet; the figures are theirs
    together. `store`: Prometheus scrapes in agent mode and sends the samples to that store (STORES).
    `icinga2_interval`: the exporter pushes the fleet to a real Icinga 2 every that many seconds.
    `shared_topic`: over DDS, every robot writes `/diagnostics`, as diagnostic_updater publishes.
    """
    plural = "s" if workers > 1 else ""
    robots = shape.robots
    setup = setup_label(shards, store, head_start, exporter_options)
    over = transport_label(transport, shared_topic)
    label = f"{fleet_label(shape, rate)}, {over}, {workers} worker{plural}{setup}"
    phases = 1 + rules  # the floor's, then the rules'
    publishing = seconds + (
        phases * (prometheus_seconds + 2 * interval) + PROMETHEUS_SETUP_SECONDS if prometheus_seconds else 0
    )
    publishing += PAGE_SECONDS if page else 0
    with (
        tempfile.TemporaryDirectory() as tmp,
        wiring(transport, Path(tmp), shared_topic) as wires,
        icinga2_receiving(Path(tmp), icinga2_interval) as icinga2,
        running_shards(
            Path(tmp),
            wires,
            shards,
            f"--ingest.workers={workers}",
            # Headroom, not a limit: the probe robot comes on top of the fleet.
            f"--fleet.max-robots={max(DEFAULT_MAX_ROBOTS, 2 * robots)}",
            "--log.level=warning",
            *([icinga2.option] if icinga2 else []),
            *exporter_options,
        ) as exporters,
        floor_counter(wires, Path(tmp), floor) as counter,
    ):
        pids = [exporter.process.pid for exporter in exporters]
        idle_rss = forest(tree_resident_bytes, pids)  # before the fleet: what they take following no robot
        started_cpu, router_cpu, started = forest(tree_cpu_seconds, pids), wires.router_cpu(), 0.0
        with running_loadgen(
            [
                *shape_arguments(shape, rate),
                *wires.loadgen_args,
                f"--wait-for-subscribers={max(60, robots / 50)}",
                f"--duration={publishing}",
                f"--head-start={head_start}",
            ],
            Path(tmp),
        ) as loadgen:
            loadgen.wait_ready(max(60, robots / 50))
            time.sleep(head_start)  # the window opens as the robots start publishing, as without a head start
            started, started_cpu = time.monotonic(), forest(tree_cpu_seconds, pids)
            router_cpu = wires.router_cpu()
            prometheus_rows: list[Row] = []
            push_rows: list[Row] = []
            with wires.probe(shard_of(exporters, PROBE_ROBOT).url, shape.components) as probe:
                # Steady: from the window's middle (the first look long over) to the check's runs.
                time.sleep(max(0.0, started + seconds / 2 - time.monotonic()))
                steady_from, steady_processes = time.monotonic(), ProcessesCpu(pids)
                pushing_from = icinga2.mark() if icinga2 else None
                steady_until = max(started + seconds - CHECK_SECONDS, steady_from + 1.0)
                steady_rss = highest_tree_resident(pids, steady_until)
                steady = steady_processes.stop()
                checked = shard_of(exporters, CHECKED_ROBOT).url
                checks = check_rows(checked, CHECKED_ROBOT)  # the last seconds of the window
                if icinga2 and pushing_from:  # while the fleet publishes: once it stops every robot changes
                    push_rows = icinga2.rows(pushing_from, metrics_text(exporters[0].url))
                if page:
                    time.sleep(max(0.0, started + seconds - time.monotonic()))
                    checks += page_rows(checked, CHECKED_ROBOT)
                if prometheus_seconds:
                    time.sleep(max(0.0, started + seconds - time.monotonic()))
                    prometheus_rows = scrape_against_floor(
                        exporters,
                        robots * shape.components,
                        Path(tmp),
                        prometheus_seconds,
                        interval,
                        floor_pieces,
                        store,
                    )
                    if rules:
                        prometheus_rows += shipped_rules_rows(
                            [exporter.url for exporter in exporters],
                            Path(tmp) / "rules",
                            prometheus_seconds,
                            interval,
                        )
                    figures = loadgen.finish()
                else:  # with the page measured, the generator's margin need not run out
                    figures = loadgen.finish() if page else loadgen.figures(seconds + 600)
        time.sleep(SETTLE_SECONDS)
        elapsed = time.monotonic() - started
        cpu = forest(tree_cpu_seconds, pids) - started_cpu
        router_cpu = wires.router_cpu() - router_cpu
        texts = [metrics_text(exporter.url) for exporter in exporters]
        counts = together([counted(text, transport) for text in texts])
        followed = [followed_robots(text) for text in texts]
        probed = probe.published if probe else 0
        got = counts.received - probed
        floor_got = counter.samples() - probed if counter else None
        rss, pss = forest(tree_resident_bytes, pids), forest(tree_proportional_bytes, pids)
        reads = [min(scrape(exporter.url) for _ in range(3)) for exporter in exporters]
        scrape_seconds, scrape_bytes = max(seconds for seconds, _ in reads), sum(size for _, size in reads)
    lost = max(0.0, figures.published - got)
    robots_followed = set().union(*followed)
    followed_twice = sum(len(robots) for robots in followed) - len(robots_followed)
    fleet = robots + (1 if probe else 0)
    components = robots * shape.components
    generator = f"(generator {figures.cpu_percent_per_1000_robots:.1f} % of a core per 1,000 robots)"
    return [
        Row("scale", f"{label}: published {generator}", figures.published, "messages"),
        Row("scale", f"{label}: lost updates", lost, "messages", "0", lost == 0),
        Row(
            "scale",
            f"{label}: robots followed (the probe's included)",
            len(robots_followed),
            "robots",
            f"{fleet}",
            len(robots_followed) == fleet,
        ),
        Row(
            "scale",
            f"{label}: robots followed by more than one shard",
            followed_twice,
            "robots",
            "0",
            followed_twice == 0,
        ),
        Row("scale", f"{label}: of which the exporter counted lost", counts.lost, "messages"),
        Row("scale", f"{label}: of which the exporter heard and dropped", counts.dropped, "messages"),
        Row(
            "scale",
            f"{label}: statuses dropped beyond fleet.max_robots",
            counts.over_cap,
            "statuses",
            "0",
            counts.over_cap == 0,
        ),
        *(
            [
                Row(
                    "scale",
                    f"{label}: lost by a subscriber that only counts (same router, same run)",
                    max(0.0, figures.published - floor_got),
                    "messages",
                ),
                Row(
                    "scale",
                    f"{label}: lost beyond it",
                    max(0.0, floor_got - got),
                    "messages",
                    "0",
                    got >= floor_got,
                ),
            ]
            if floor_got is not None
            else []
        ),
        Row("scale", f"{label}: exporter CPU", cpu / elapsed * 100, "% of a core", "<= 100", cpu <= elapsed),
        Row("scale", f"{label}: exporter CPU a message", cpu / max(got, 1) * 1e6, "µs"),
        Row(
            "scale",
            f"{label}: {STEADY_CPU_A_MESSAGE}",
            steady.whole / steady.seconds / (robots * rate) * 1e6,
            "µs",
        ),
        *steady.rows(label, robots * rate),
        Row(
            "scale",
            f"{label}: exporter memory a component (resident, all its processes)",
            rss / components,
            "bytes",
            f"<= {MEMORY_TARGET}",
            rss / components <= MEMORY_TARGET,
        ),
        Row(
            "scale",
            f"{label}: the most in the steady window (read every second)",
            steady_rss / components,
            "bytes",
            f"<= {MEMORY_TARGET}",
            steady_rss / components <= MEMORY_TARGET,
        ),
        Row(
            "scale",
            f"{label}: proportional (PSS: pages the processes share counted once)",
            pss / components,
            "bytes",
        ),
        Row(
            "scale",
            f"{label}: of which beyond its processes' own ({idle_rss / 1e6:.0f} MB following no robot)",
            (rss - idle_rss) / components,
            "bytes",
        ),
        *(
            [Row("scale", f"{label}: router CPU", router_cpu / elapsed * 100, "% of a core")]
            if wires.router
            else []
        ),
        Row("scale", f"{label}: events written", counts.events_written, "events"),
        Row(
            "scale",
            f"{label}: events dropped",
            counts.events_dropped,
            "events",
            "0",
            counts.events_dropped == 0,
        ),
        *(
            [
                Row(
                    "scale",
                    f"{label}: renders ahead of Prometheus's scrapes",
                    counts.renders_ahead,
                    "renders",
                ),
                Row(
                    "scale",
                    f"{label}: renders again after them, until the scrape",
                    counts.render_ahead_passes,
                    "passes",
                ),
                Row(
                    "scale",
                    f"{label}: scrapes not rendered ahead of, after futile passes",
                    counts.render_ahead_skipped,
                    "scrapes",
                ),
                Row("scale", f"{label}: the last render ahead took", counts.render_ahead_seconds, "s"),
            ]
            if prometheus_seconds
            else []
        ),
        Row("scale", f"{label}: /metrics read", scrape_seconds, "s"),  # the slowest shard's
        Row("scale", f"{label}: /metrics body", scrape_bytes / 1e6, "MB"),  # every shard's
        *(probe.rows(label) if probe else []),
    ] + [replace(row, figure=f"{label}: {row.figure}") for row in checks + prometheus_rows + push_rows]


def positive_counts(flag: str, text: str, most: int | None = None) -> list[int]:
    """`text`'s comma-separated whole numbers, each from 1 to `most`; ValueError naming `flag` otherwise."""
    counts = []
    for part in text.split(","):
        try:
            count = int(part)
        except ValueError:
            raise ValueError(f"{flag}: expected comma-separated whole numbers, got {text!r}") from None
        if count < 1:
            raise ValueError(f"{flag}: each must be at least 1, got {count}")
        if most is not None and count > most:
            raise ValueError(f"{flag}: each must be at most {most}, got {count}")
        counts.append(count)
    return counts


def check_window(options: argparse.Namespace) -> None:
    """ValueError naming the first of the run's lengths that cannot measure anything."""
    if not options.seconds > 0:
        raise ValueError(f"--seconds: must be positive, got {options.seconds}")
    if not options.prometheus_seconds >= 0:
        raise ValueError(f"--prometheus-seconds: must not be negative, got {options.prometheus_seconds}")
    if options.scrape_interval < 1:
        raise ValueError(f"--scrape-interval: must be at least 1 s, got {options.scrape_interval}")
    if options.rules and not options.prometheus_seconds:
        raise ValueError("--rules: needs --prometheus-seconds (the rules run in that Prometheus)")
    if options.floor_pieces and not options.prometheus_seconds:
        raise ValueError("--floor-pieces: needs --prometheus-seconds (that Prometheus scrapes it)")
    if options.prometheus_agent and not options.prometheus_seconds:
        raise ValueError("--prometheus-agent: needs --prometheus-seconds (that Prometheus is the agent)")
    if not 1 <= options.shards <= MAX_SHARDS:
        raise ValueError(f"--shards: must be from 1 to {MAX_SHARDS}, got {options.shards}")
    check_head_start(options.head_start)
    if options.icinga2 is not None and not options.icinga2 > 0:
        raise ValueError(f"--icinga2: the push's interval must be positive, got {options.icinga2}")
    if options.icinga2 is not None and options.shards > 1:
        raise ValueError("--icinga2: with one exporter only (each shard would push as its own exporter)")
    if options.dds_shared_topic and options.transport != DDS:
        raise ValueError("--dds-shared-topic: needs --transport dds")
    if options.floor and options.transport != ZENOH:
        raise ValueError("--floor: its counting subscriber hears the fleet through the Zenoh router only")


def main(argv: Sequence[str] | None = None) -> None:
    """Every size x worker count asked for, one after the other."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="1000", help="comma-separated fleet sizes (default 1000)")
    parser.add_argument("--workers", default="1,2", help="comma-separated worker counts (default 1,2)")
    parser.add_argument("--transport", default=ZENOH, choices=TRANSPORTS, help="zenoh (default) or dds")
    parser.add_argument(
        "--dds-shared-topic",
        action="store_true",
        help="with --transport dds: every robot writes the absolute /diagnostics, its node named in the ROS "
        "graph, as diagnostic_updater publishes (default: rt/<robot>/diagnostics_agg each)",
    )
    parser.add_argument("--seconds", type=float, default=60)
    parser.add_argument(
        "--prometheus-seconds",
        type=float,
        default=0,
        help="Prometheus scrapes it after",
    )
    parser.add_argument("--scrape-interval", type=int, default=30, help="Prometheus's (s)")
    parser.add_argument(
        "--exporter-option", action="append", default=[], help="passed to `overseer run` (repeat for several)"
    )
    parser.add_argument(
        "--rules", action="store_true", help="then the shipped rules too (with --prometheus-seconds)"
    )
    parser.add_argument(
        "--floor",
        action="store_true",
        help="a subscriber that only counts hears the fleet beside the exporter (Zenoh): the router's losses",
    )
    parser.add_argument(
        "--page",
        action="store_true",
        help="then Chromium loads the status page, the JSON API and event history are read, under traffic",
    )
    parser.add_argument(
        "--head-start",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="the robots are declared SECONDS before they first publish (default 0: all start at once)",
    )
    parser.add_argument(
        "--floor-pieces",
        action="store_true",
        help="Prometheus also scrapes the floor's text in the exporter's gzip pieces (--prometheus-seconds)",
    )
    parser.add_argument(
        "--shards",
        type=int,
        default=1,
        help=f"exporters sharing the fleet (--shard I/N, --workers each; 1 to {MAX_SHARDS}, default 1)",
    )
    parser.add_argument(
        "--prometheus-agent",
        nargs="?",
        const="prometheus",
        choices=STORES,
        metavar="STORE",
        help=f"Prometheus scrapes as an agent into STORE ({' or '.join(STORES)}; --prometheus-seconds)",
    )
    parser.add_argument(
        "--icinga2",
        nargs="?",
        const=60.0,
        type=float,
        metavar="SECONDS",
        help="the exporter pushes the fleet to a real Icinga 2 every SECONDS (default 60)",
    )
    add_shape_arguments(parser)
    options = parser.parse_args(argv)
    try:  # before any server starts: a run refused after minutes of setup measures nothing
        sizes = positive_counts("--robots", options.robots)
        worker_counts = positive_counts("--workers", options.workers, MAX_INGEST_WORKERS)
        check_shape(options)
        check_window(options)
    except ValueError as error:
        parser.error(str(error))
    rows: list[Row] = []
    for robots in sizes:
        runs: list[tuple[int, list[Row]]] = []
        for workers in worker_counts:
            measured = run(
                shape_of(options, robots),
                workers,
                options.seconds,
                options.prometheus_seconds,
                options.scrape_interval,
                tuple(options.exporter_option),
                options.rules,
                options.transport,
                options.rate,
                options.floor,
                options.page,
                options.head_start,
                options.floor_pieces,
                options.shards,
                options.prometheus_agent,
                options.icinga2,
                options.dds_shared_topic,
            )
            runs.append((workers, measured))
            rows += measured
        if options.shards == 1:  # with shards, a worker's share would be of its shard's, not the fleet's
            transport = transport_label(options.transport, options.dds_shared_topic)
            fleet = f"{fleet_label(shape_of(options, robots), options.rate)}, {transport}"
            setup = setup_label(1, options.prometheus_agent, options.head_start, options.exporter_option)
            rows += compared_with_one_worker(fleet, setup, runs)
    emit(rows)


if __name__ == "__main__":
    main()
