"""The load generator: N robots' diagnostics at their rate, through the real wire protocols.

`python -m bench.loadgen --robots 10000 --zenoh.connect tcp/127.0.0.1:7447 --duration 60` publishes
10,000 robots x 50 components at 1 Hz as rmw_zenoh publishes them (`--transport dds`: raw writes on
one loopback-only Cyclone participant). Each robot's array is encoded once; a publication patches its
stamp, and the change profile patches the few values it changes (`loadgen_payloads`); each second's
publications are spread evenly over the second, robot by robot, in slices of 1 to 10 ms, not in a burst.

It measures itself: the CPU it used while publishing (every thread of the process, the middleware's
included), as a share of one core and per 1,000 robots, the messages it published, those it sent late
(more than a tenth of a period after they were due) or skipped (a whole period behind), and the
statuses it changed. It prints a line `ready` (and writes `--ready-file`) once every robot is declared,
waits with `--wait-for-subscribers` until every robot has a subscriber (and `--head-start` seconds more,
for a fleet declared before it publishes), and ends with human lines and one JSON line of `LoadFigures`.
Benchmarks start it with `start_loadgen` and read those figures.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import signal
import struct
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

from bench.common import repo_on_path
from bench.loadgen_payloads import LIVE, PROFILES, REALISTIC, Fleet, FleetShape, leaf_count
from bench.loadgen_wire import DDS, TRANSPORTS, ZENOH, DdsWire, Wire, ZenohEndpoints, ZenohWire
from testbed.processes import RunningProcess, spawn

# Each second's publications go out in slices of about SLICE_MESSAGES, from 10 ms apart (100 a second) to
# 1 ms apart: a burst of 400 kB every 10 ms (10,000 robots) overflows a Zenoh router's queue toward a
# subscriber, and waking 1,000 times a second costs 5 % of a core at 1,000 robots.
SLICE_MESSAGES = 10
SLICE_SECONDS = (0.001, 0.01)
LATE_SHARE = 0.1  # a publication sent more than this share of a period after it was due is late
SUBSCRIBER_POLL_SECONDS = 0.5
_STAMP = struct.Struct("<iI")
_ROS_NAMESPACE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")


@dataclass(frozen=True)
class LoadSettings:
    """What to publish, over what, for how long."""

    shape: FleetShape
    rate: float = 1.0  # publications a robot a second
    transport: str = ZENOH
    zenoh: ZenohEndpoints = field(default_factory=ZenohEndpoints)
    domain: int = 0  # ROS domain: the Zenoh keys' first chunk, or the DDS domain
    dds_shared_topic: bool = False  # DDS: every robot on `/diagnostics`, as diagnostic_updater publishes
    namespace_prefix: str = "robot"  # robots are PREFIX1 ... PREFIXN
    duration: float | None = None  # seconds of publishing; None: until stopped
    wait_for_subscribers: float = 0.0  # seconds to wait, before publishing, for every robot to be matched
    head_start: float = 0.0  # seconds the robots are declared (their subscribers found) before they publish
    ready_file: str | None = None

    def robot_names(self) -> list[str]:
        """Every robot's name, which is its namespace."""
        return [f"{self.namespace_prefix}{index + 1}" for index in range(self.shape.robots)]


@dataclass(frozen=True)
class LoadFigures:
    """What one run published and what it cost."""

    robots: int
    components: int
    rate: float
    transport: str
    profile: str
    seconds: float  # of publishing, wall clock
    cpu_seconds: float  # of the whole process while publishing
    cpu_percent: float  # of one core
    cpu_percent_per_1000_robots: float
    published: int
    late: int  # sent more than LATE_SHARE of a period after they were due
    missed: int  # not sent: the generator was a whole period behind
    failed: int  # refused by the middleware
    statuses_changed: int
    went_down: int
    came_back: int
    setup_seconds: float  # encoding the fleet and declaring every robot
    subscribed_after: float | None  # seconds until every robot was matched; None: not waited, or never

    def summary(self) -> list[str]:
        """The figures as lines for a person."""
        return [
            f"published {self.published:,} messages in {self.seconds:.1f} s ({self.late:,} late, "
            f"{self.missed:,} missed, {self.failed:,} refused); changed {self.statuses_changed:,} statuses; "
            f"{self.went_down:,} robots went down, {self.came_back:,} came back",
            f"CPU {self.cpu_seconds:.2f} s: {self.cpu_percent:.1f} % of a core, "
            f"{self.cpu_percent_per_1000_robots:.2f} % of a core per 1,000 robots",
        ]


class Pacing:
    """Which robots are due at a moment: robot i of n publishes at i / (n x rate) past each period's start.

    Publication p (robot p mod n) is due p / (n x rate) seconds after the start, so a period's
    publications are spread evenly over it, whoever calls and however late.
    """

    def __init__(self, robots: int, rate: float) -> None:
        """Pace `robots` robots at `rate` publications a second each, from elapsed time 0."""
        self.robots, self.per_second = robots, robots * rate
        self.late_after = LATE_SHARE / rate
        self.pending = 0  # the next publication to send
        self.late = 0  # sent more than `late_after` after they were due
        self.missed = 0  # skipped: a whole period behind

    def due(self, elapsed: float) -> list[range]:
        """The robots to publish now, `elapsed` seconds after the start, as ranges in publication order."""
        due = int(elapsed * self.per_second) + 1
        if due - self.pending > self.robots:  # a whole period behind: only the last period's are sent
            self.missed += due - self.robots - self.pending
            self.pending = due - self.robots
        late_by_now = math.floor((elapsed - self.late_after) * self.per_second) + 1
        self.late += max(0, min(due, late_by_now) - self.pending)
        ranges = []
        while self.pending < due:
            first = self.pending % self.robots
            stop = min(self.robots, first + due - self.pending)
            ranges.append(range(first, stop))
            self.pending += stop - first
        return ranges

    def next_due(self) -> float:
        """Seconds after the start when the next publication is due."""
        return self.pending / self.per_second


class LoadGenerator:
    """Publishes a fleet through a wire at its rate, changing it as its profile says, and measures itself."""

    def __init__(self, settings: LoadSettings, wire: Wire) -> None:
        """Get ready to publish `settings`' fleet through `wire`; nothing happens until `run`."""
        self.settings = settings
        self.wire = wire
        self._stop = threading.Event()

    def stop(self) -> None:
        """Ask `run` to return (its figures count what was published until then)."""
        self._stop.set()

    def run(self) -> LoadFigures:
        """Declare every robot, say ready, wait for subscribers if asked, publish; the figures."""
        settings, wire = self.settings, self.wire
        robots = settings.shape.robots
        setup_started = time.monotonic()
        fleet = Fleet(settings.shape)
        for robot in range(robots):
            wire.open(robot)
        wire.declared()
        setup_seconds = time.monotonic() - setup_started
        print(f"ready: {robots} robots declared in {setup_seconds:.1f} s", flush=True)
        if settings.ready_file:
            Path(settings.ready_file).write_text("ready\n")
        subscribed_after = self._wait_for_subscribers() if settings.wait_for_subscribers else None
        if settings.head_start:
            print(f"publishing in {settings.head_start:g} s", flush=True)
            self._stop.wait(settings.head_start)
        pacing = Pacing(robots, settings.rate)
        slice_seconds = min(SLICE_SECONDS[1], max(SLICE_SECONDS[0], SLICE_MESSAGES / pacing.per_second))
        live = settings.shape.profile == LIVE
        started, cpu_started = time.monotonic(), time.process_time()
        fleet.advance(started)
        published = went_down = came_back = 0
        while not self._stop.is_set():
            now = time.monotonic()
            elapsed = now - started
            if settings.duration is not None and elapsed >= settings.duration:
                break
            down, back = fleet.advance(now)
            for robot in down:
                wire.close(robot)
            for robot in back:
                wire.open(robot)
            if down or back:
                wire.declared()
            went_down, came_back = went_down + len(down), came_back + len(back)
            stamp = _STAMP.pack(*divmod(time.time_ns(), 1_000_000_000))
            for due in pacing.due(elapsed):
                if live:
                    fleet.turn(due.start, due.stop)
                published += wire.publish(due.start, due.stop, fleet.payloads, stamp)
            self._stop.wait(max(slice_seconds, started + pacing.next_due() - time.monotonic()))
        seconds, cpu = time.monotonic() - started, time.process_time() - cpu_started
        wire.shut()
        cpu_percent = cpu / seconds * 100 if seconds > 0 else 0.0
        return LoadFigures(
            robots=robots,
            components=settings.shape.components,
            rate=settings.rate,
            transport=settings.transport,
            profile=settings.shape.profile,
            seconds=round(seconds, 3),
            cpu_seconds=round(cpu, 3),
            cpu_percent=round(cpu_percent, 2),
            cpu_percent_per_1000_robots=round(cpu_percent * 1000 / robots, 3),
            published=published,
            late=pacing.late,
            missed=pacing.missed,
            failed=wire.failed,
            statuses_changed=fleet.changed,
            went_down=went_down,
            came_back=came_back,
            setup_seconds=round(setup_seconds, 3),
            subscribed_after=subscribed_after,
        )

    def _wait_for_subscribers(self) -> float | None:
        """Seconds until every robot has a subscriber; None when `wait_for_subscribers` passed first."""
        started = time.monotonic()
        deadline = started + self.settings.wait_for_subscribers
        while not self._stop.is_set() and time.monotonic() < deadline:
            if self.wire.every_robot_subscribed():
                waited = time.monotonic() - started
                print(f"every robot has a subscriber after {waited:.1f} s", flush=True)
                return round(waited, 3)
            self._stop.wait(SUBSCRIBER_POLL_SECONDS)
        print(f"not every robot has a subscriber after {self.settings.wait_for_subscribers:g} s", flush=True)
        return None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The fleet, its change profile, the wire and the run's length."""
    parser.add_argument("--robots", type=int, default=1000, help="number of robots (default 1000)")
    add_shape_arguments(parser)
    add_wire_arguments(parser)


def add_shape_arguments(parser: argparse.ArgumentParser) -> None:
    """What a robot publishes, how often, and how the fleet changes (all but the number of robots)."""
    parser.add_argument(
        "--components",
        type=int,
        default=50,
        help="statuses an array, leaves and their groups (default 50: 45 leaves in 5 groups)",
    )
    parser.add_argument("--rate", type=float, default=1.0, help="publications a robot a second (default 1)")
    parser.add_argument(
        "--profile",
        choices=PROFILES,
        default=REALISTIC,
        help="realistic: a share of the statuses changes each second; live: every value changes at every "
        "publication (default realistic)",
    )
    parser.add_argument(
        "--change-share",
        type=float,
        default=0.01,
        metavar="SHARE",
        help="share of all statuses changing each second, realistic profile (default 0.01)",
    )
    parser.add_argument(
        "--trouble-share",
        type=float,
        default=0.02,
        metavar="SHARE",
        help="share of robots with a leaf in ERROR and one in WARN (default 0.02)",
    )
    parser.add_argument(
        "--down-share",
        type=float,
        default=0.0,
        metavar="SHARE",
        help="share of robots going down each minute (default 0)",
    )
    parser.add_argument(
        "--down-seconds", type=float, default=30.0, help="how long a robot stays down (default 30)"
    )
    parser.add_argument("--seed", type=int, default=1, help="seed of the change profile (default 1)")


def add_wire_arguments(parser: argparse.ArgumentParser) -> None:
    """The robots' names, the wire they publish on and the run's length."""
    parser.add_argument("--namespace-prefix", default="robot", help="robots are PREFIX1..PREFIXN")
    parser.add_argument("--transport", choices=TRANSPORTS, default=ZENOH, help="zenoh (default) or dds")
    parser.add_argument(
        "--zenoh.connect", dest="zenoh_connect", action="append", default=[], metavar="ENDPOINT"
    )
    parser.add_argument(
        "--zenoh.listen", dest="zenoh_listen", action="append", default=[], metavar="ENDPOINT"
    )
    parser.add_argument("--zenoh.mode", dest="zenoh_mode", choices=["peer", "client"], default="peer")
    parser.add_argument(
        "--robots-per-session",
        type=int,
        default=1000,
        metavar="N",
        help="robots sharing one Zenoh session (default 1000)",
    )
    parser.add_argument("--domain", type=int, default=0, help="ROS domain id (default 0)")
    parser.add_argument(
        "--dds-shared-topic",
        dest="dds_shared_topic",
        action="store_true",
        help="DDS: every robot writes the absolute /diagnostics, its node named in the ROS graph, as "
        "diagnostic_updater publishes (default: rt/<robot>/diagnostics_agg each)",
    )
    parser.add_argument("--duration", type=float, help="seconds of publishing (default: until stopped)")
    parser.add_argument(
        "--wait-for-subscribers",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="before publishing, wait up to SECONDS until every robot has a subscriber",
    )
    parser.add_argument(
        "--head-start",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="the robots are declared SECONDS before they first publish (default 0: the fleet starts all at "
        "once)",
    )
    parser.add_argument("--ready-file", help="written once every robot's publisher is declared")


def settings_of(args: argparse.Namespace) -> LoadSettings:
    """The run the arguments ask for; ValueError naming the first bad argument."""
    if args.robots < 1:
        raise ValueError(f"--robots: must be at least 1, got {args.robots}")
    check_shape(args)
    if args.robots_per_session < 1:
        raise ValueError(f"--robots-per-session: must be at least 1, got {args.robots_per_session}")
    check_head_start(args.head_start)
    if not _ROS_NAMESPACE.fullmatch(args.namespace_prefix):
        raise ValueError(f"--namespace-prefix: expected ROS name tokens, got {args.namespace_prefix!r}")
    return LoadSettings(
        shape=shape_of(args, args.robots),
        rate=args.rate,
        transport=args.transport,
        zenoh=ZenohEndpoints(
            tuple(args.zenoh_connect),
            tuple(args.zenoh_listen),
            args.zenoh_mode,
            args.robots_per_session,
        ),
        domain=args.domain,
        dds_shared_topic=args.dds_shared_topic,
        namespace_prefix=args.namespace_prefix,
        duration=args.duration,
        wait_for_subscribers=args.wait_for_subscribers,
        head_start=args.head_start,
        ready_file=args.ready_file,
    )


def check_head_start(seconds: float) -> None:
    """ValueError unless `seconds` is a head start the generator can wait: finite and not negative."""
    if not (math.isfinite(seconds) and seconds >= 0):
        raise ValueError(f"--head-start: must be a finite number of seconds, not negative, got {seconds}")


def check_shape(args: argparse.Namespace) -> None:
    """ValueError naming the first of `add_shape_arguments`' arguments the generator would refuse."""
    try:
        leaf_count(args.components)
    except ValueError as error:
        raise ValueError(f"--components: {error}") from None
    if not args.rate > 0:
        raise ValueError(f"--rate: must be positive, got {args.rate}")
    for name in ("change_share", "trouble_share", "down_share"):
        if not 0.0 <= getattr(args, name) <= 1.0:
            flag = "--" + name.replace("_", "-")
            raise ValueError(f"{flag}: expected a share from 0 to 1, got {getattr(args, name)}")
    if not args.down_seconds >= 0:
        raise ValueError(f"--down-seconds: must not be negative, got {args.down_seconds}")


def shape_of(args: argparse.Namespace, robots: int) -> FleetShape:
    """The fleet of `robots` that `add_shape_arguments`' arguments describe."""
    return FleetShape(
        robots=robots,
        components=args.components,
        profile=args.profile,
        change_share=args.change_share,
        trouble_share=args.trouble_share,
        down_share=args.down_share,
        down_seconds=args.down_seconds,
        seed=args.seed,
    )


def shape_arguments(shape: FleetShape, rate: float) -> list[str]:
    """The generator's arguments for `shape` at `rate` publications a robot a second."""
    return [
        f"--robots={shape.robots}",
        f"--components={shape.components}",
        f"--rate={rate!r}",
        f"--profile={shape.profile}",
        f"--change-share={shape.change_share!r}",
        f"--trouble-share={shape.trouble_share!r}",
        f"--down-share={shape.down_share!r}",
        f"--down-seconds={shape.down_seconds!r}",
        f"--seed={shape.seed}",
    ]


def wire_of(settings: LoadSettings) -> Wire:
    """The transport the settings ask for, opened."""
    if settings.transport == DDS:
        return DdsWire(settings.robot_names(), settings.domain, settings.dds_shared_topic)
    return ZenohWire(settings.robot_names(), settings.domain, settings.zenoh)


def main(argv: Sequence[str] | None = None) -> int:
    """Publish until SIGTERM, SIGINT or `--duration`; print the figures."""
    parser = argparse.ArgumentParser(prog="python -m bench.loadgen", description=__doc__.splitlines()[0])
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        settings = settings_of(args)
    except ValueError as error:
        parser.error(str(error))
    shape = settings.shape
    change = f"{shape.change_share:.1%} of statuses a second" if shape.profile == REALISTIC else "every value"
    print(
        f"loadgen: {shape.robots:,} robots x {shape.components} components at {settings.rate:g} Hz over "
        f"{settings.transport}, {shape.profile} profile ({change} changing, {shape.trouble_share:.1%} of "
        f"robots in trouble, {shape.down_share:.1%} going down a minute)",
        flush=True,
    )
    generator = LoadGenerator(settings, wire_of(settings))
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: generator.stop())
    figures = generator.run()
    for line in figures.summary():
        print(line)
    print(json.dumps(asdict(figures)), flush=True)
    return 0


@dataclass
class LoadgenProcess(RunningProcess):
    """A load generator running in a process of its own."""

    ready_file: Path

    def wait_ready(self, timeout: float) -> None:
        """Wait until every robot is declared; RuntimeError if the process ends first."""
        deadline = time.monotonic() + timeout
        while not self.ready_file.exists():
            if self.process.poll() is not None:
                raise RuntimeError(f"loadgen exited with {self.process.returncode}:\n{self.log()[-3000:]}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"loadgen not ready after {timeout}s:\n{self.log()[-3000:]}")
            time.sleep(0.1)

    def figures(self, timeout: float) -> LoadFigures:
        """Wait for the run to end (its `--duration`, or `stop`) and read its figures."""
        self.process.wait(timeout)
        lines = [line for line in self.log().splitlines() if line.startswith("{")]
        if self.process.returncode != 0 or not lines:
            raise RuntimeError(f"loadgen failed ({self.process.returncode}):\n{self.log()[-3000:]}")
        return LoadFigures(**json.loads(lines[-1]))

    def finish(self, timeout: float = 120.0) -> LoadFigures:
        """Stop publishing now and read the figures."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        return self.figures(timeout)


def start_loadgen(arguments: Sequence[str], directory: Path) -> LoadgenProcess:
    """Start `python -m bench.loadgen ARGUMENTS` with its output and ready file in `directory`."""
    stamp = time.monotonic_ns()
    ready_file, log_path = directory / f"loadgen-{stamp}.ready", directory / f"loadgen-{stamp}.log"
    args = [sys.executable, "-m", "bench.loadgen", *arguments, f"--ready-file={ready_file}"]
    process = spawn(args, log_path, env=repo_on_path())
    return LoadgenProcess(process, log_path, ready_file)


@contextmanager
def running_loadgen(arguments: Sequence[str], directory: Path) -> Iterator[LoadgenProcess]:
    """A load generator for the block, always stopped at its end."""
    loadgen = start_loadgen(arguments, directory)
    try:
        yield loadgen
    finally:
        loadgen.stop()


if __name__ == "__main__":
    sys.exit(main())
