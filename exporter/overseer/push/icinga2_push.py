"""The push loop: registers every robot in Icinga 2 and delivers its check results.

It reads the fleet's digests every tick (`fleet.robot_digests()`), then a snapshot of only the robots
it has results to queue for. A robot whose level (or up/down, or set of components) changed has its
results queued as urgent at once; every robot's results are queued again every `interval`, each robot at
its own phase of it (`icinga2_schedule`), a few hundred robots asked of the fleet at a time. Pending
results are kept as the latest one per host and service, never as a queue of every intermediate one,
so after an outage Icinga gets the state now; beyond a few thousand, robots are owed theirs, built from
a fresh snapshot as the queue empties. The hosts and services the results need are made, and those of
robots forgotten deleted, by `icinga2_objects`: one a call, or many in one config package stage.
"""

from __future__ import annotations

import itertools
import logging
import math
import threading
import time
from collections.abc import Callable, Container, Iterator
from typing import Any

from overseer.config.icinga2 import Icinga2Config
from overseer.fleet.interface import Fleet, FleetPartUnavailable
from overseer.maintenance.effects import EffectStats
from overseer.maintenance.schedule import MaintenanceSchedule, RobotMaintenance
from overseer.model import FleetSnapshot, RobotState
from overseer.push.icinga2_client import Icinga2Client, Icinga2Error, error_text
from overseer.push.icinga2_downtimes import Icinga2Downtimes
from overseer.push.icinga2_labels import HostLabels
from overseer.push.icinga2_metrics import PushStats
from overseer.push.icinga2_names import GROUP_SERVICE_PREFIX, host_name, original_name
from overseer.push.icinga2_objects import Icinga2Objects
from overseer.push.icinga2_package import RELOADING_REASONS
from overseer.push.icinga2_results import (
    CheckResult,
    ResultKey,
    robot_groups,
    robot_results,
    robot_services,
)
from overseer.push.icinga2_schedule import next_due
from overseer.push.retry import Retry
from overseer.push.shared_sets import SharedSets
from overseer.verdict import Maintenance

log = logging.getLogger(__name__)

TICK_SECONDS = 0.25
BATCH_SECONDS = 0.5  # deliver for at most this long before looking at the fleet again
PIPELINED_RESULTS = 50  # results sent in one write, their answers read after
SNAPSHOT_ROBOTS = 500  # robots asked of the fleet at once, their results queued before the next are asked
# Results built and held at once: further robots are owed theirs, built as these are delivered. A fleet
# first heard would otherwise hold every robot's (70,000 at 10,000 robots, 100 MB) through its first stage.
QUEUED_RESULTS = 2000
RELOAD_SECONDS = 30.0  # Icinga's API away this long while a stage is deployed is a reload; longer, a failure


class Icinga2Push:
    """Keeps Icinga 2's hosts and services in step with the fleet."""

    def __init__(
        self,
        config: Icinga2Config,
        fleet: Fleet,
        expire_after: float,
        stats: PushStats | None = None,
        clock: Callable[[], float] = time.monotonic,
        maintenance: MaintenanceSchedule | None = None,
    ) -> None:
        """Push `fleet` per `config`; hosts of robots not seen within `expire_after` of start are deleted.

        With `maintenance`, robots in a maintenance window have their hosts and services in downtime.
        """
        self._config = config
        self._fleet = fleet
        self.stats = stats or PushStats()
        self._clock = clock
        self._client = Icinga2Client(config)
        self.downtime_stats = EffectStats("icinga2")
        self._downtimes = (
            None if maintenance is None else Icinga2Downtimes(self._client, maintenance, self.downtime_stats)
        )
        self._labels = HostLabels(self._client)
        self._objects = Icinga2Objects(
            config, self._client, self._labels, self._downtimes, self.stats, expire_after
        )
        self._maintenance = maintenance
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self._urgent: dict[ResultKey, CheckResult] = {}
        self._pending: dict[ResultKey, CheckResult] = {}
        self._signatures: dict[str, tuple[int, RobotMaintenance | None]] = {}  # robot → digest, maintenance
        self._due: dict[str, float] = {}
        self._sets = SharedSets()  # one object for each distinct set of groups
        self._groups: dict[str, frozenset[str]] = {}  # robot → every group it had since it was first pushed
        self._robot_hosts: dict[str, str] = {}  # robot → host, for every robot being pushed
        self._retry = Retry("Icinga 2 push", log)
        self._owed: dict[str, bool] = {}  # robot → urgent, for robots whose results wait for room to be built
        # A result was queued or owed since the last look whose object may not exist.
        self._unmade_queued = True
        self._away_since: float | None = None  # Icinga's API away since, while a stage was deployed

    def start(self) -> None:
        """Run the loop in a daemon thread."""
        self._thread = threading.Thread(target=self._run, name="icinga2-push", daemon=True)
        self._thread.start()
        log.info("pushing to Icinga 2 at %s every %gs", self._config.url, self._config.interval)

    def stop(self) -> None:
        """Stop the loop and close the connection."""
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout=self._config.timeout + 5)
        self._objects.close()
        self._client.close()

    def _run(self) -> None:
        while not self._stopping.is_set():
            behind = False
            try:
                behind = self.step()
            except Exception:  # the push must never take the exporter down; it tries again next tick
                log.exception("Icinga 2 push: unexpected error")
                self._retry.pause(self._clock() + self._retry.backoff)
            self._stopping.wait(0 if behind else TICK_SECONDS)

    def step(self) -> bool:
        """One tick: queue what changed or is due, then deliver for a while if Icinga is not backed off.

        True when delivering ran out of time with results still waiting: the next tick need not wait.
        """
        now = self._clock()
        try:
            self._queue(now)
        except FleetPartUnavailable as error:
            # A robot missing from a partial snapshot is no robot gone: wait for the whole fleet.
            log.info("Icinga 2 push: not queueing this tick, %s", error)
        behind = self._retry.due(now) and self._deliver(now) and self._queued() > 0
        self.stats.set_pending(self._queued() + sum(self._key_count(robot) for robot in self._owed))
        return behind

    def _queue(self, now: float) -> None:
        digests = self._fleet.robot_digests()
        schedule = self._maintenance
        active = [] if schedule is None else schedule.active(schedule.clock())
        signatures: dict[str, tuple[int, RobotMaintenance | None]] = {}
        for name, digest in digests.items():
            if digest is None:
                continue  # what it reports is unknown until it speaks again: Icinga keeps its last results
            signature = (digest, None if schedule is None else schedule.state(name, active))
            if signature != self._signatures.get(name) or now >= self._due.get(name, 0.0):
                signatures[name] = signature
        host_waits, hosts = self._objects.host_waits_for_stage, self._robot_hosts
        waiting = [  # those whose host waits for a stage are not asked for: they would be owed again
            name
            for name in self._owed
            if name not in signatures and digests.get(name) is not None and not host_waits(hosts[name])
        ]
        self._queue_in_turn(signatures, waiting, now)
        for gone in [name for name in self._robot_hosts if name not in digests]:
            host = self._robot_hosts.pop(gone)
            self._signatures.pop(gone, None)
            self._due.pop(gone, None)
            self._groups.pop(gone, None)
            self._owed.pop(gone, None)
            self._labels.forget(host)
            for queue in (self._urgent, self._pending):
                for key in [key for key in queue if key[0] == host]:
                    del queue[key]
            self._objects.forget(host)
            log.info("robot %s was forgotten: deleting its Icinga 2 objects", gone)

    def _queue_in_turn(
        self, looked_at: dict[str, tuple[int, RobotMaintenance | None]], waiting: list[str], now: float
    ) -> None:
        """Build the results of the robots `looked_at` (their new signatures) and `waiting`, as room allows.

        In turn: changes owed, changes new, repeats owed, repeats new; a robot left out is owed its
        results. Every robot looked at is asked of the fleet, a few hundred at a time (at 10,000 robots
        over ingest workers the whole fleet is tens of megabytes to pickle), so that its objects are
        registered with the rest; one waiting only while there is room.
        """
        since = {name: order for order, name in enumerate(self._owed)}  # the first owed goes first

        def turn(name: str) -> tuple[bool, bool, int]:
            changed = name in looked_at and looked_at[name] != self._signatures.get(name)
            urgent = self._owed.get(name, False) or changed
            return not urgent, name not in since, since.get(name, 0)

        for names in self._asks(sorted([*looked_at, *waiting], key=turn), looked_at):
            snapshot = self._fleet.robots_snapshot(names)
            robots = {robot.name: robot for robot in snapshot.robots}  # in the fleet's order, not the turn's
            for robot in (robots[name] for name in names if name in robots):
                urgent = self._owed.get(robot.name, False)
                if robot.name in looked_at:
                    signature = looked_at[robot.name]
                    urgent = urgent or signature != self._signatures.get(robot.name)
                    self._signatures[robot.name] = signature
                self._know(robot)
                if self._queued() < QUEUED_RESULTS and not self._waits_for_stage(robot.name):
                    self._queue_results(snapshot, robot, urgent, now)
                else:
                    self._owe(robot.name, urgent)

    def _asks(self, names: list[str], looked_at: Container[str]) -> Iterator[list[str]]:
        """`names` in asks of the fleet, leaving out robots not `looked_at` once the queue has no room."""
        room = QUEUED_RESULTS - self._queued()  # an estimate: robots heard for the first time have no groups
        ask: list[str] = []
        for name in names:
            if name not in looked_at and room <= 0:
                continue
            room -= self._key_count(name)
            ask.append(name)
            if len(ask) == SNAPSHOT_ROBOTS:
                yield ask
                room, ask = QUEUED_RESULTS - self._queued(), []
        if ask:
            yield ask

    def _know(self, robot: RobotState) -> None:
        """Note what `robot`'s objects are: its host, its labels, every group it had."""
        host = self._robot_hosts.setdefault(robot.name, host_name(robot.name))
        self._labels.want(host, robot.listing.labels if robot.listing is not None else ())
        self._objects.seen(host)
        known = self._groups.get(robot.name)
        groups = set(robot_groups(robot))
        groups.update(  # and those whose services an earlier run of ours made
            original_name(service.removeprefix(GROUP_SERVICE_PREFIX))
            for service in self._objects.services_made(host)
            if service.startswith(GROUP_SERVICE_PREFIX)
        )
        if known is None or not groups <= known:
            self._groups[robot.name] = self._sets.share(groups.union(known or ()))

    def _queue_results(self, snapshot: FleetSnapshot, robot: RobotState, urgent: bool, now: float) -> None:
        """Queue `robot`'s results now: urgent when its level changed, else as the interval's repeat."""
        state = self._signatures[robot.name][1]
        maintenance = (
            None if state is None else Maintenance(state.window, state.until, state.author, state.comment)
        )
        target = self._urgent if urgent else self._pending
        groups = sorted(self._groups[robot.name])
        for result in robot_results(snapshot, robot, self._config.services, groups, maintenance):
            if not self._unmade_queued and not self._objects.made(result.key):
                self._unmade_queued = True
            self._pending.pop(result.key, None)
            if result.key not in self._urgent:
                target[result.key] = result
            else:
                self._urgent[result.key] = result
        self._owed.pop(robot.name, None)
        self._due[robot.name] = next_due(robot.name, now, self._config.interval)

    def _owe(self, robot: str, urgent: bool) -> None:
        """Leave `robot`'s results to be built once the queue has room; its objects are registered before.

        Its results still queued are dropped: those built later replace them, and a robot's results are
        either queued or owed, never counted twice.
        """
        keys = self._keys(robot)
        # A change still undelivered keeps the robot urgent: owed as a repeat, it would wait behind them all.
        urgent = urgent or self._owed.get(robot, False) or any(key in self._urgent for key in keys)
        self._owed[robot] = urgent
        self._due[robot] = math.inf  # no repeat while owed: its next moment counts from when it is built
        for key in keys:
            self._urgent.pop(key, None)
            self._pending.pop(key, None)
        if not self._unmade_queued and not all(self._objects.made(key) for key in keys):
            self._unmade_queued = True

    def _waits_for_stage(self, robot: str) -> bool:
        """Whether an object of `robot`'s waits for a stage: so do its results."""
        objects = self._objects
        return objects.stage_in_flight and any(map(objects.waits_for_stage, self._keys(robot)))

    def _owe_waiting_for_stage(self) -> None:
        """While a stage is deployed, robots with a result queued whose object waits for a stage owe it.

        Delivered now, their objects would be made one a call: beside the stage that makes them, or one
        at a time where the next stage would make them all.
        """
        waits = self._objects.waits_for_stage
        hosts = {key[0] for queue in (self._urgent, self._pending) for key in queue if waits(key)}
        if hosts:
            for robot in [robot for robot, host in self._robot_hosts.items() if host in hosts]:
                self._owe(robot, False)

    def _keys(self, robot: str) -> list[ResultKey]:
        """The keys of `robot`'s results: its host's, then its services'."""
        host = self._robot_hosts[robot]
        services = robot_services(self._config.services, sorted(self._groups[robot]))
        return [(host, ""), *((host, service) for service, _ in services)]

    def _key_count(self, robot: str) -> int:
        """How many results `robot` has, as far as its groups are known: `len(self._keys(robot))`, cheaply."""
        services = self._config.services
        return 1 + ("robot" in services) + ("groups" in services) * len(self._groups.get(robot, ()))

    def _queued(self) -> int:
        """How many results are built and queued."""
        return len(self._urgent) + len(self._pending)

    def _wanted_keys(self) -> Iterator[ResultKey]:
        """The keys of every result queued or owed."""
        owed = (key for robot in self._owed for key in self._keys(robot))
        return itertools.chain(self._urgent, self._pending, owed)

    def _deliver(self, now: float) -> bool:
        """Deliver queued results for up to `BATCH_SECONDS`; False when Icinga failed (then backed off)."""
        deadline = now + BATCH_SECONDS
        try:
            objects = self._objects
            if not objects.found:
                objects.find(now, set(self._robot_hosts.values()))
            objects.end_stage(now)
            objects.delete_forgotten(now)
            if self._unmade_queued and objects.register_in_bulk(self._wanted_keys(), now):
                self._unmade_queued = False
            if objects.stage_in_flight:
                self._owe_waiting_for_stage()
            if self._downtimes is not None and self._downtimes.due(objects.created):
                # Before the results (and, after a restart, right after finding our hosts): a host in a
                # window is in downtime when its robot's DOWN arrives, or its TTL runs out.
                self._downtimes.sync(objects.created)
            self._labels.sync(objects.created)
            attempted = 0
            for queue in (self._urgent, self._pending):
                while queue and (attempted == 0 or self._clock() < deadline):
                    batch = list(itertools.islice(queue.items(), PIPELINED_RESULTS))
                    attempted += self._push(batch, queue, deadline)
        except Icinga2Error as error:
            if self._reloading(error, now):
                # Icinga reloads to run the stage: what it did not answer stays queued, no failure of its.
                self._retry.pause(now + TICK_SECONDS)
                return False
            self._failed(error, now)
            return False
        self._away_since = None
        self._retry.succeeded(f"Icinga 2 at {self._config.url} accepts results again")
        return True

    def _reloading(self, error: Icinga2Error, now: float) -> bool:
        """Whether `error` is Icinga's API away while it reloads to run a stage, for `RELOAD_SECONDS` at most.

        Beyond that, or with no stage deployed, it is a failure (Icinga down, its certificate expired).
        """
        if not self._objects.stage_in_flight or error.reason not in RELOADING_REASONS:
            return False
        if self._away_since is None:
            self._away_since = now
        return now - self._away_since < RELOAD_SECONDS

    def _failed(self, error: Icinga2Error, now: float) -> None:
        self.stats.failed(error.reason)
        text = str(error)
        if error.status == 401:
            text = (
                f"Icinga 2 at {self._config.url} refused the credentials (HTTP 401): check icinga2.username "
                "and icinga2.password_file, or the client certificate"
            )
        self._retry.failed(text, now)

    def _push(
        self, batch: list[tuple[ResultKey, CheckResult]], queue: dict[ResultKey, CheckResult], deadline: float
    ) -> int:
        """Deliver `batch` in one pipelined write, objects created first; settled results leave `queue`.

        The results looked at: those after `deadline` stay queued when objects made one a call took the
        time (a level change waits for no more than one). Raises Icinga2Error for the first result Icinga
        failed, or when its answers stopped: that result and those after it stay queued.
        """
        sent: list[tuple[ResultKey, CheckResult]] = []
        bodies = []
        looked = 0
        for key, result in batch:
            if looked and self._clock() >= deadline:
                break
            looked += 1
            body = self._body(result)
            if body is None:
                del queue[key]  # dropped: not ours to push
            else:
                sent.append((key, result))
                bodies.append(body)
        answers, error = self._client.pipeline("/v1/actions/process-check-result", bodies)
        delivered = 0
        try:
            for (key, result), (status, document) in zip(sent, answers, strict=False):
                delivered += self._settled(result, status, document)
                del queue[key]
        finally:
            if delivered:
                self.stats.delivered(delivered, time.time())
        if error is not None:
            try:
                raise error
            finally:
                del error  # or the frame its traceback holds would hold it: a cycle (see Icinga2Client)
        return looked

    def _body(self, result: CheckResult) -> dict[str, Any] | None:
        """The result's `process-check-result` body, its host or service created first; None when dropped."""
        if not self._objects.ready(result):
            return None
        body: dict[str, Any] = {
            "type": "Service" if result.service else "Host",
            "exit_status": result.exit_status,
            "plugin_output": result.plugin_output,
            "performance_data": list(result.performance_data),
            "ttl": self._config.ttl,
            "check_source": f"overseer/{self._config.exporter_id}",
        }
        if result.service:
            body["service"] = f"{result.host}!{result.service}"
        else:
            body["host"] = result.host
        return body

    def _settled(self, result: CheckResult, status: int, document: Any) -> bool:
        """Whether Icinga took the result; a 404 is forgotten (made again next time), other failures raise."""
        if status == 404:  # deleted behind our back (or Icinga lost it): create it again next time
            self.stats.failed("http_404")
            self._objects.lost(result)
            return False
        if not 200 <= status < 300:
            raise Icinga2Error(
                f"http_{status}", f"process-check-result: HTTP {status}: {error_text(document)}", status
            )
        return True
