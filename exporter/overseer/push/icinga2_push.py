"""The push loop: registers every robot in Icinga 2 and delivers its check results.

It reads the fleet's digests every tick (`fleet.robot_digests()`), then a snapshot of only the robots
it has results to queue for. A robot whose level (or up/down, or set of components) changed has its
results queued as urgent at once; every robot's results are queued again every `interval`, each robot at
its own phase of it (`icinga2_schedule`), a few hundred robots asked of the fleet at a time. Pending
results are kept as the latest one per host and service, never as a queue of every intermediate one,
so after an outage Icinga gets the state now; beyond a few thousand, robots are owed theirs, built from
a fresh snapshot as the queue empties. Objects are created on first need and marked with
`vars.overseer_exporter`; only objects with this exporter's mark are ever changed or deleted. Many
objects new at once (a fleet first heard, or its groups) are registered in one stage of the exporter's
config package (`icinga2_package`) where the ApiUser may, as one object a call would take Icinga 2
hours at 10,000 robots.
"""

from __future__ import annotations

import itertools
import logging
import math
import threading
import time
from collections.abc import Callable, Container, Iterator, Mapping
from collections.abc import Set as AbstractSet
from typing import Any

from overseer.config.icinga2 import Icinga2Config
from overseer.fleet.interface import Fleet, FleetPartUnavailable
from overseer.maintenance.effects import EffectStats
from overseer.maintenance.schedule import MaintenanceSchedule, RobotMaintenance
from overseer.model import FleetSnapshot, RobotState
from overseer.push.icinga2_client import Icinga2Client, Icinga2Error, error_text, object_path
from overseer.push.icinga2_downtimes import Icinga2Downtimes
from overseer.push.icinga2_labels import HostLabels
from overseer.push.icinga2_metrics import PushStats
from overseer.push.icinga2_names import GROUP_SERVICE_PREFIX, host_name, original_name, robot_name
from overseer.push.icinga2_package import ConfigPackage, PackageRefused, PackageRejected, object_text
from overseer.push.icinga2_results import (
    CheckResult,
    ResultKey,
    robot_groups,
    robot_results,
    robot_services,
)
from overseer.push.icinga2_schedule import next_due
from overseer.push.retry import Retry
from overseer.push.shared_sets import NO_NAMES, SharedSets
from overseer.verdict import Maintenance

log = logging.getLogger(__name__)

TICK_SECONDS = 0.25
BATCH_SECONDS = 0.5  # deliver for at most this long before looking at the fleet again
PIPELINED_RESULTS = 50  # results sent in one write, their answers read after
SNAPSHOT_ROBOTS = 500  # robots asked of the fleet at once, their results queued before the next are asked
# Results built and held at once: further robots are owed theirs, built as these are delivered. A fleet
# first heard would otherwise hold every robot's (70,000 at 10,000 robots, 100 MB) through its first stage.
QUEUED_RESULTS = 2000
SILENT_TEXT = "UNKNOWN - no result from the Overseer exporter within its TTL: the exporter is silent"
HOST_SILENT_TEXT = "DOWN - no result from the Overseer exporter within its TTL: the exporter is silent"
# Active checks only run once a pushed result's TTL ran out; then `dummy` says the exporter is silent.
FALLBACK_CHECK_INTERVAL = 86400.0
BULK_OBJECTS = 100  # objects to register at once from which a config package stage beats one call each
DEPLOY_SECONDS = 600.0  # how long a stage may take to validate and load (a minute or two at 100,000 objects)
PACKAGE_PAUSE_SECONDS = 600.0  # after Icinga rejected a stage, one call an object for this long


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
        self._expire_after = expire_after
        self.stats = stats or PushStats()
        self._clock = clock
        self._client = Icinga2Client(config)
        self.downtime_stats = EffectStats("icinga2")
        self._downtimes = (
            None if maintenance is None else Icinga2Downtimes(self._client, maintenance, self.downtime_stats)
        )
        self._maintenance = maintenance
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self._urgent: dict[ResultKey, CheckResult] = {}
        self._pending: dict[ResultKey, CheckResult] = {}
        self._signatures: dict[str, tuple[int, RobotMaintenance | None]] = {}  # robot → digest, maintenance
        self._due: dict[str, float] = {}
        self._sets = SharedSets()  # the sets below, one object for each distinct set
        self._groups: dict[str, frozenset[str]] = {}  # robot → every group it had since it was first pushed
        self._robot_hosts: dict[str, str] = {}  # robot → host, for every robot being pushed
        self._created: dict[str, frozenset[str]] | None = None  # our hosts → our services; None until synced
        self._foreign: set[str] = set()  # hosts of the same name not made by this exporter
        self._orphans: dict[str, float] = {}  # our hosts found at start, not yet seen: → deletion time
        self._to_delete: set[str] = set()
        self._labels = HostLabels(self._client)
        self._retry = Retry("Icinga 2 push", log)
        self._package: ConfigPackage | None = ConfigPackage(self._client, config.exporter_id, DEPLOY_SECONDS)
        self._package_paused_until = 0.0
        self._packaged: dict[str, frozenset[str]] = {}  # hosts of the package → their services in it
        self._owed: dict[str, bool] = {}  # robot → urgent, for robots whose results wait for room to be built
        # A result was queued or owed since the last look whose object may not exist.
        self._unmade_queued = True

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
        self._client.close()

    def _run(self) -> None:
        while not self._stopping.is_set():
            try:
                self.step()
            except Exception:  # the push must never take the exporter down; it tries again next tick
                log.exception("Icinga 2 push: unexpected error")
                self._retry.pause(self._clock() + self._retry.backoff)
            self._stopping.wait(TICK_SECONDS)

    def step(self) -> None:
        """One tick: queue what changed or is due, then deliver for a while if Icinga is not backed off."""
        now = self._clock()
        try:
            self._queue(now)
        except FleetPartUnavailable as error:
            # A robot missing from a partial snapshot is no robot gone: wait for the whole fleet.
            log.info("Icinga 2 push: not queueing this tick, %s", error)
        if self._retry.due(now):
            self._deliver(now)
        self.stats.set_pending(self._queued() + sum(self._key_count(robot) for robot in self._owed))

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
        waiting = [name for name in self._owed if name not in signatures and digests.get(name) is not None]
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
            self._to_delete.add(host)
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
                if self._queued() < QUEUED_RESULTS:
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
        self._orphans.pop(host, None)
        self._to_delete.discard(host)
        known = self._groups.get(robot.name)
        groups = set(robot_groups(robot))
        if self._created is not None:  # and those whose services an earlier run of ours made
            groups.update(
                original_name(service.removeprefix(GROUP_SERVICE_PREFIX))
                for service in self._created.get(host, ())
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
            if not self._unmade_queued and not self._made(result.key):
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
        if not self._unmade_queued and not all(self._made(key) for key in keys):
            self._unmade_queued = True

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

    def _deliver(self, now: float) -> None:
        deadline = now + BATCH_SECONDS
        try:
            if self._created is None:
                self._created = self._find_own_objects(now)
            self._delete_forgotten(now)
            self._register_in_bulk(now)
            if self._downtimes is not None and self._downtimes.due(self._created):
                # Before the results (and, after a restart, right after finding our hosts): a host in a
                # window is in downtime when its robot's DOWN arrives, or its TTL runs out.
                self._downtimes.sync(self._created)
            self._labels.sync(self._created)
            attempted = 0
            for queue in (self._urgent, self._pending):
                while queue and (attempted == 0 or self._clock() < deadline):
                    batch = list(itertools.islice(queue.items(), PIPELINED_RESULTS))
                    attempted += self._push(batch, queue, deadline)
        except Icinga2Error as error:
            self._failed(error, now)
            return
        self._retry.succeeded(f"Icinga 2 at {self._config.url} accepts results again")

    def _failed(self, error: Icinga2Error, now: float) -> None:
        self.stats.failed(error.reason)
        text = str(error)
        if error.status == 401:
            text = (
                f"Icinga 2 at {self._config.url} refused the credentials (HTTP 401): check icinga2.username "
                "and icinga2.password_file, or the client certificate"
            )
        self._retry.failed(text, now)

    def _find_own_objects(self, now: float) -> dict[str, frozenset[str]]:
        """The hosts and services this exporter made earlier (before a restart of either side).

        No filter expression is sent (Icinga 2.15.4+ may refuse them to a narrow ApiUser): the ApiUser's
        own permission filter already limits the answer to marked objects, and the mark is checked here.
        """
        mark = self._config.exporter_id
        package = None if self._package is None else self._package.name
        hosts = self._client.expect("GET", "/v1/objects/hosts", {"attrs": ["name", "vars", "package"]})
        created: dict[str, set[str]] = {
            item["name"]: set() for item in hosts["results"] if _exporter_of(item) == mark
        }
        packaged: dict[str, set[str]] = {}
        for item in hosts["results"]:
            if item["name"] in created:
                self._labels.found(item["name"], item.get("attrs", {}).get("vars") or {})
                if item.get("attrs", {}).get("package") == package:
                    packaged[item["name"]] = set()
        services = self._client.expect(
            "GET", "/v1/objects/services", {"attrs": ["name", "host_name", "vars", "package"]}
        )
        for item in services["results"]:
            host = item["attrs"]["host_name"]
            if _exporter_of(item) == mark and host in created:
                created[host].add(item["attrs"]["name"])
                if host in packaged and item["attrs"].get("package") == package:
                    packaged[host].add(item["attrs"]["name"])
        self._packaged.update((host, self._sets.share(services)) for host, services in packaged.items())
        known = set(self._robot_hosts.values())
        for host in created:
            if host not in known:
                self._orphans[host] = now + self._expire_after
        log.info("found %d hosts of this exporter (%s) in Icinga 2", len(created), mark)
        return {host: self._sets.share(services) for host, services in created.items()}

    def _delete_forgotten(self, now: float) -> None:
        assert self._created is not None
        for host, when in list(self._orphans.items()):
            if now >= when:
                self._to_delete.add(host)
                del self._orphans[host]
        self._unpackage([host for host in self._to_delete if host in self._packaged])
        for host in list(self._to_delete):
            if host in self._created:
                status, _ = self._client.request("DELETE", object_path("hosts", host) + "?cascade=1")
                if status not in (200, 404):
                    raise Icinga2Error(f"http_{status}", f"deleting host {host}: HTTP {status}", status)
                del self._created[host]
            self._to_delete.discard(host)

    def _unpackage(self, hosts: list[str]) -> None:
        """Delete hosts of the package: the services added by a call each first, then a stage without them."""
        if not hosts:
            return
        assert self._created is not None
        for host in hosts:
            for service in self._created.get(host, NO_NAMES) - self._packaged[host]:
                status, _ = self._client.request("DELETE", object_path("services", host, service))
                if status not in (200, 404):
                    raise Icinga2Error(
                        f"http_{status}", f"deleting service {host}!{service}: HTTP {status}", status
                    )
        kept = {host: services for host, services in self._packaged.items() if host not in hosts}
        try:
            self._deploy(kept, lambda: not self._exists(object_path("hosts", hosts[0])))
            self.stats.staged("ok")
        except (PackageRefused, PackageRejected) as error:
            self.stats.staged("refused" if isinstance(error, PackageRefused) else "rejected")
            log.warning(
                "Icinga 2 refused a stage of package %s without the %d forgotten robots' hosts (%s): they "
                "stay in Icinga 2 until a stage is accepted",
                self._package_name(),
                len(hosts),
                error,
            )
        for host in hosts:
            del self._packaged[host]
            self._created.pop(host, None)
            self._to_delete.discard(host)

    def _register_in_bulk(self, now: float) -> None:
        """Register the objects the queued and owed results need in one stage, when they are many.

        New hosts with their services, and new services of the package's hosts: robots declared before
        they publish (an inventory, tokens heard first) get their hosts before their groups are known.
        """
        if self._package is None or now < self._package_paused_until or not self._unmade_queued:
            return
        assert self._created is not None
        created = self._created
        wanted = self._unmade_wanted()
        services_wanted = sum(len(services) for services in wanted.values())
        hosts_wanted = len(wanted.keys() - created.keys())
        if hosts_wanted + services_wanted < BULK_OBJECTS:
            self._unmade_queued = False
            return  # made one object a call as their results are delivered
        newest = self._newest(wanted)
        packaged, share = self._packaged, self._sets.share
        staged = {host: share(packaged.get(host, NO_NAMES) | services) for host, services in wanted.items()}
        try:
            self._deploy({**self._packaged, **staged}, lambda: self._exists(newest))
        except PackageRefused as error:
            self.stats.staged("refused")
            log.info(
                "Icinga 2 registers robots one object a call: the ApiUser may not deploy config packages "
                "(%s); with config/query and config/modify a fleet's robots are registered at once",
                error,
            )
            self._package = None
            return
        except PackageRejected as error:
            self.stats.staged("rejected")
            log.warning(
                "Icinga 2 rejected a stage of package %s registering %d robots (%s): registering them one "
                "object a call for %gs",
                self._package.name,
                len(wanted),
                error,
                PACKAGE_PAUSE_SECONDS,
            )
            self._package_paused_until = now + PACKAGE_PAUSE_SECONDS
            return
        self.stats.staged("ok")
        self._unmade_queued = False
        for host, services in staged.items():
            self._packaged[host] = services
            created[host] = made = self._sets.share(created.get(host, NO_NAMES) | services)
            if self._downtimes is not None:
                self._downtimes.cover(host, made)
        log.info(
            "Icinga 2: %d hosts and %d services registered in one stage of package %s",
            hosts_wanted,
            services_wanted,
            self._package.name,
        )

    def _unmade_wanted(self) -> dict[str, set[str]]:
        """Queued and owed results' objects a stage may register: hosts not made, services missing from ours.

        A service missing from a host made one object a call stays for a call of its own: Icinga cannot
        delete (cascading) a host made by a call while a package holds one of its services.
        """
        assert self._created is not None
        created, packaged, foreign = self._created, self._packaged, self._foreign
        wanted: dict[str, set[str]] = {}
        owed = (key for robot in self._owed for key in self._keys(robot))
        for host, service in itertools.chain(self._urgent, self._pending, owed):
            made = created.get(host)
            if made is None:
                if host in foreign:
                    continue
                services = wanted.setdefault(host, set())
            elif not service or service in made or host not in packaged:
                continue
            else:
                services = wanted.setdefault(host, set())
            if service:
                services.add(service)
        return wanted

    def _newest(self, wanted: dict[str, set[str]]) -> str:
        """The API path of an object the stage adds: once it exists, Icinga runs the stage."""
        assert self._created is not None
        for host in wanted:
            if host not in self._created:
                return object_path("hosts", host)
        host, services = next(iter(wanted.items()))
        return object_path("services", host, min(services))

    def _made(self, key: ResultKey) -> bool:
        """Whether the object of a result with this key exists, as far as this exporter knows."""
        if self._created is None:
            return False
        host, service = key
        if host in self._foreign:
            return True  # never pushed: nothing to register
        made = self._created.get(host)
        return made is not None and (not service or service in made)

    def _deploy(self, hosts: Mapping[str, AbstractSet[str]], loaded: Callable[[], bool]) -> None:
        """Make `hosts` and their services the package's content; raises what `ConfigPackage.deploy` does."""
        if self._package is None:
            raise PackageRefused("config packages are not used")
        self._package.deploy(self._stage_text(hosts), loaded)

    def _stage_text(self, hosts: Mapping[str, AbstractSet[str]]) -> str:
        """The package's content for `hosts` and their services, as one text.

        Its objects' texts are let go before the stage is deployed: at 10,000 robots, 70,000 small strings
        (30 MB) that would otherwise stay in Python's arenas while Icinga validates and loads the stage.
        """
        texts = []
        for host in sorted(hosts):
            variables = (
                self._labels.variables(host) if host not in self._packaged else self._labels.current(host)
            )
            texts.append(
                object_text("Host", host, self._host_attrs(host, variables), self._config.host_template)
            )
            for service in sorted(hosts[host]):
                attrs = self._service_attrs()
                texts.append(object_text("Service", service, attrs, self._config.service_template, host))
        return "".join(texts)

    def _package_name(self) -> str:
        return "(none)" if self._package is None else self._package.name

    def _exists(self, path: str) -> bool:
        status, document = self._client.request("GET", path, {"attrs": ["name"]})
        if status not in (200, 404):
            reason = error_text(document)
            raise Icinga2Error(f"http_{status}", f"reading {path}: HTTP {status}: {reason}", status)
        return status == 200

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
        assert self._created is not None
        if result.host in self._foreign:
            return None
        made = result.host not in self._created
        attrs = self._host_attrs(result.host, self._labels.variables(result.host)) if made else {}
        if made and not self._create("hosts", result.host, "", attrs):
            return None
        if result.service and result.service not in self._created[result.host]:
            made = self._create("services", result.host, result.service, self._service_attrs()) or made
        if made and self._downtimes is not None:  # in its window's downtime before its first result
            self._downtimes.cover(result.host, self._created[result.host])
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
        assert self._created is not None
        if status == 404:  # deleted behind our back (or Icinga lost it): create it again next time
            self.stats.failed("http_404")
            if result.service:
                made = self._created.get(result.host)
                if made is not None:
                    self._created[result.host] = self._sets.share(made - {result.service})
            else:
                self._created.pop(result.host, None)
                self._packaged.pop(result.host, None)  # the package is gone too, or a stage would clash
            return False
        if not 200 <= status < 300:
            raise Icinga2Error(
                f"http_{status}", f"process-check-result: HTTP {status}: {error_text(document)}", status
            )
        return True

    def _create(self, kind: str, host: str, service: str, attrs: dict[str, Any]) -> bool:
        """PUT one object; an existing one of ours is taken over, one not ours is left alone (False)."""
        assert self._created is not None
        template = self._config.service_template if service else self._config.host_template
        body: dict[str, Any] = {"attrs": attrs}
        if template:
            body["templates"] = [template]
        path = object_path(kind, host, service)
        status, document = self._client.request("PUT", path, body)
        if not 200 <= status < 300:
            if "already exists" not in error_text(document):
                raise Icinga2Error(
                    f"http_{status}", f"creating {path}: HTTP {status}: {error_text(document)}", status
                )
            if not self._is_ours(path):  # taken: by us before a restart, or by someone else
                if service:
                    log.warning(
                        "Icinga 2 service %s!%s exists and was not made by this exporter: left alone",
                        host,
                        service,
                    )
                    return False
                log.warning(
                    "Icinga 2 host %s exists and was not made by this exporter: its robot is not pushed", host
                )
                self._foreign.add(host)
                return False
        if service:
            self._created[host] = self._sets.share(self._created.get(host, NO_NAMES) | {service})
        else:
            self._created.setdefault(host, NO_NAMES)
            log.info("Icinga 2 host %s ready", host)
        return True

    def _is_ours(self, path: str) -> bool:
        status, document = self._client.request("GET", path, {"attrs": ["vars"]})
        if status == 404:  # hidden from us by the ApiUser's filter: not ours
            return False
        if status != 200:
            raise Icinga2Error(
                f"http_{status}", f"reading {path}: HTTP {status}: {error_text(document)}", status
            )
        return _exporter_of(document["results"][0]) == self._config.exporter_id

    def _marks(self) -> dict[str, Any]:
        return {"overseer_managed": True, "overseer_exporter": self._config.exporter_id, "dummy_state": 3}

    def _host_attrs(self, host: str, labels: dict[str, Any]) -> dict[str, Any]:
        return self._passive_attrs({**labels, "ros_robot": robot_name(host), "dummy_text": HOST_SILENT_TEXT})

    def _service_attrs(self) -> dict[str, Any]:
        return self._passive_attrs({"dummy_text": SILENT_TEXT})

    def _passive_attrs(self, variables: dict[str, Any]) -> dict[str, Any]:
        """Pushed results only; when they stop for their TTL, `dummy` runs and says the exporter is silent."""
        return self._with_zone(
            {
                "check_command": "dummy",
                "enable_active_checks": True,
                "enable_passive_checks": True,
                "check_interval": FALLBACK_CHECK_INTERVAL,
                "retry_interval": FALLBACK_CHECK_INTERVAL,
                "max_check_attempts": 1,
                # One attribute per variable, so that the variables of an imported template are kept:
                # a whole `vars` dictionary would replace them.
                **{f"vars.{name}": value for name, value in {**self._marks(), **variables}.items()},
            }
        )

    def _with_zone(self, attrs: dict[str, Any]) -> dict[str, Any]:
        if self._config.zone:
            attrs["zone"] = self._config.zone
        return attrs


def _exporter_of(item: dict[str, Any]) -> object:
    """The exporter id an object of a query answer is marked with (None: unmarked)."""
    variables = item.get("attrs", {}).get("vars") or {}
    return variables.get("overseer_exporter") if isinstance(variables, dict) else None
