"""The hosts and services this exporter made in Icinga 2: found, made one a call or in a stage, deleted.

Every object is marked with `vars.overseer_exporter`; only objects with this exporter's mark are ever
changed or deleted, and a host of a robot's name that is not ours is left alone, its robot not pushed.
Objects are made on a result's first need, one a call; many new at once (a fleet first heard, or its
groups) are registered in one stage of the exporter's config package (`icinga2_package`) where the
ApiUser may, as one object a call would take Icinga 2 hours at 10,000 robots.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Collection, Iterable, Mapping
from collections.abc import Set as AbstractSet
from typing import Any

from overseer.config.icinga2 import Icinga2Config
from overseer.push.icinga2_client import Icinga2Client, Icinga2Error, error_text, object_path
from overseer.push.icinga2_downtimes import Icinga2Downtimes
from overseer.push.icinga2_labels import HostLabels
from overseer.push.icinga2_metrics import PushStats
from overseer.push.icinga2_names import robot_name
from overseer.push.icinga2_package import ConfigPackage, PackageRefused, PackageRejected, object_text
from overseer.push.icinga2_results import CheckResult, ResultKey
from overseer.push.icinga2_stage import StageInFlight
from overseer.push.shared_sets import NO_NAMES, SharedSets

log = logging.getLogger(__name__)

SILENT_TEXT = "UNKNOWN - no result from the Overseer exporter within its TTL: the exporter is silent"
HOST_SILENT_TEXT = "DOWN - no result from the Overseer exporter within its TTL: the exporter is silent"
# Active checks only run once a pushed result's TTL ran out; then `dummy` says the exporter is silent.
FALLBACK_CHECK_INTERVAL = 86400.0
BULK_OBJECTS = 100  # objects to register at once from which a config package stage beats one call each
DEPLOY_SECONDS = 600.0  # how long a stage may take to validate and load (a minute or two at 100,000 objects)
PACKAGE_PAUSE_SECONDS = 600.0  # after Icinga rejected a stage, one call an object for this long


class Icinga2Objects:
    """The hosts and services this exporter made in Icinga 2, and the calls and stages that change them."""

    def __init__(
        self,
        config: Icinga2Config,
        client: Icinga2Client,
        labels: HostLabels,
        downtimes: Icinga2Downtimes | None,
        stats: PushStats,
        expire_after: float,
    ) -> None:
        """Objects per `config` through `client`; hosts found at start, unseen for `expire_after`, go."""
        self._config = config
        self._client = client
        self._labels = labels
        self._downtimes = downtimes
        self._stats = stats
        self._expire_after = expire_after
        self._sets = SharedSets()  # the sets below, one object for each distinct set
        self._created: dict[str, frozenset[str]] | None = None  # our hosts → our services; None until found
        self._foreign: set[str] = set()  # hosts of the same name not made by this exporter
        self._orphans: dict[str, float] = {}  # our hosts found at start, not yet seen: → deletion time
        self._to_delete: set[str] = set()
        self._stopping = threading.Event()
        # A stage deploys beside the push's deliveries: on a connection of its own.
        self._stage_client = Icinga2Client(config)
        self._package: ConfigPackage | None = ConfigPackage(
            self._stage_client, config.exporter_id, DEPLOY_SECONDS, sleep=self._stage_sleep
        )
        self._package_paused_until = 0.0
        self._packaged: dict[str, frozenset[str]] = {}  # hosts of the package → their services in it
        self._stage: StageInFlight | None = None

    def close(self) -> None:
        """Stop waiting for a stage being deployed, and drop its connection."""
        self._stopping.set()
        if self._stage is not None:
            self._stage.join(self._config.timeout + 1)
        self._stage_client.close()

    def _stage_sleep(self, seconds: float) -> None:
        """A deploy's wait between two looks at Icinga, cut short (Icinga2Error) when the push stops."""
        if self._stopping.wait(seconds):
            raise Icinga2Error("stopped", "the push stopped while a stage was being deployed")

    @property
    def stage_in_flight(self) -> bool:
        """Whether a stage is being deployed, or ended and not yet taken into account (`end_stage`)."""
        return self._stage is not None

    def waits_for_stage(self, key: ResultKey) -> bool:
        """Whether the object of a result with `key` waits for a stage: the one deployed, or the next.

        A new host, or a new service of a host of the package; a new service of a host made one a call
        is made one a call, as a stage would not register it (`unmade_wanted`).
        """
        if self._stage is None or self.made(key):
            return False
        host = key[0]
        return host not in self.created or host in self._packaged

    def host_waits_for_stage(self, host: str) -> bool:
        """Whether `host` waits for a stage, or the stage deployed registers services of it."""
        return self._stage is not None and (host in self._stage.staged or self.waits_for_stage((host, "")))

    def end_stage(self, now: float) -> None:
        """Take the stage deployed into account once it ended: its objects made, or the package given up.

        Raises Icinga2Error when its deploy failed.
        """
        if self._stage is not None and self._stage.done:
            self._stage_ended(now)

    @property
    def found(self) -> bool:
        """Whether this exporter's objects were looked for in Icinga since it started."""
        return self._created is not None

    @property
    def created(self) -> Mapping[str, frozenset[str]]:
        """Each host this exporter made (found, or made since) → its services; only once `found`."""
        assert self._created is not None
        return self._created

    def services_made(self, host: str) -> frozenset[str]:
        """The services of `host` this exporter made, as far as it knows (none before they are found)."""
        return NO_NAMES if self._created is None else self._created.get(host, NO_NAMES)

    def seen(self, host: str) -> None:
        """`host`'s robot is in the fleet: not an orphan, not to be deleted."""
        self._orphans.pop(host, None)
        self._to_delete.discard(host)

    def forget(self, host: str) -> None:
        """`host`'s robot was forgotten: its host and services are deleted at the next delivery."""
        self._to_delete.add(host)

    def find(self, now: float, known_hosts: Collection[str]) -> None:
        """Find the hosts and services this exporter made earlier (before a restart of either side).

        Those not in `known_hosts` are deleted `expire_after` from `now` unless their robots are seen.

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
        for host in created:
            if host not in known_hosts:
                self._orphans[host] = now + self._expire_after
        log.info("found %d hosts of this exporter (%s) in Icinga 2", len(created), mark)
        self._created = {host: self._sets.share(services) for host, services in created.items()}

    def delete_forgotten(self, now: float) -> None:
        """Delete the hosts of robots forgotten, and of those found at start and not seen since.

        While a stage is deployed, those of the package or of the stage wait for it to end: a stage
        without them now would race it.
        """
        assert self._created is not None
        for host, when in list(self._orphans.items()):
            if now >= when:
                self._to_delete.add(host)
                del self._orphans[host]
        stage = self._stage
        if stage is None:
            self._unpackage([host for host in self._to_delete if host in self._packaged])
        for host in list(self._to_delete):
            if stage is not None and (host in self._packaged or host in stage.staged):
                continue
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
            self._stats.staged("ok")
        except (PackageRefused, PackageRejected) as error:
            self._stats.staged("refused" if isinstance(error, PackageRefused) else "rejected")
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

    def register_in_bulk(self, keys: Iterable[ResultKey], now: float) -> bool:
        """Register the objects of results with these `keys` in one stage, when they are many.

        New hosts with their services, and new services of the package's hosts: robots declared before
        they publish (an inventory, tokens heard first) get their hosts before their groups are known.
        True when they are registered, or few enough to be made one a call; False while a stage deploys
        them (in a thread of its own: `stage_in_flight`), and when the package is not used,
        paused, or Icinga would not take its stage. Raises Icinga2Error when a stage's deploy failed.
        """
        self.end_stage(now)
        if self._stage is not None:
            return False
        if self._package is None or now < self._package_paused_until:
            return False
        assert self._created is not None
        created = self._created
        wanted = self.unmade_wanted(keys)
        services_wanted = sum(len(services) for services in wanted.values())
        hosts_wanted = len(wanted.keys() - created.keys())
        if hosts_wanted + services_wanted < BULK_OBJECTS:
            return True  # made one object a call as their results are delivered
        newest = self._newest(wanted)
        packaged, share = self._packaged, self._sets.share
        staged = {host: share(packaged.get(host, NO_NAMES) | services) for host, services in wanted.items()}
        package, text = self._package, self._stage_text({**self._packaged, **staged})
        self._stage = StageInFlight(
            staged,
            hosts_wanted,
            services_wanted,
            lambda: package.deploy(text, lambda: self._exists(newest, self._stage_client)),
        )
        return False

    def _stage_ended(self, now: float) -> None:
        """Take the ended stage's outcome into account: its objects made, or the package given up."""
        assert self._stage is not None and self._created is not None and self._package is not None
        stage, self._stage = self._stage, None
        staged, created = stage.staged, self._created
        try:
            stage.raise_failure()
        except PackageRefused as error:
            self._stats.staged("refused")
            log.info(
                "Icinga 2 registers robots one object a call: the ApiUser may not deploy config packages "
                "(%s); with config/query and config/modify a fleet's robots are registered at once",
                error,
            )
            self._package = None
            return
        except PackageRejected as error:
            self._stats.staged("rejected")
            log.warning(
                "Icinga 2 rejected a stage of package %s registering %d robots (%s): registering them one "
                "object a call for %gs",
                self._package.name,
                len(staged),
                error,
                PACKAGE_PAUSE_SECONDS,
            )
            self._package_paused_until = now + PACKAGE_PAUSE_SECONDS
            return
        self._stats.staged("ok")
        for host, services in staged.items():
            self._packaged[host] = services
            created[host] = self._sets.share(created.get(host, NO_NAMES) | services)
        if self._downtimes is not None:  # after every host is known staged: a failure here leaves none out
            for host in staged:
                self._downtimes.cover(host, created[host])
        log.info(
            "Icinga 2: %d hosts and %d services registered in one stage of package %s",
            stage.hosts,
            stage.services,
            self._package.name,
        )

    def unmade_wanted(self, keys: Iterable[ResultKey]) -> dict[str, set[str]]:
        """The objects of results with `keys` a stage may register: hosts not made, services not ours.

        A service missing from a host made one object a call stays for a call of its own: Icinga cannot
        delete (cascading) a host made by a call while a package holds one of its services.
        """
        assert self._created is not None
        created, packaged, foreign = self._created, self._packaged, self._foreign
        wanted: dict[str, set[str]] = {}
        for host, service in keys:
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

    def made(self, key: ResultKey) -> bool:
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

    def _exists(self, path: str, client: Icinga2Client | None = None) -> bool:
        status, document = (client or self._client).request("GET", path, {"attrs": ["name"]})
        if status not in (200, 404):
            reason = error_text(document)
            raise Icinga2Error(f"http_{status}", f"reading {path}: HTTP {status}: {reason}", status)
        return status == 200

    def ready(self, result: CheckResult) -> bool:
        """Make `result`'s host or service where missing, in any window's downtime; False: not ours."""
        assert self._created is not None
        if result.host in self._foreign:
            return False
        made = result.host not in self._created
        attrs = self._host_attrs(result.host, self._labels.variables(result.host)) if made else {}
        if made and not self._create("hosts", result.host, "", attrs):
            return False
        if result.service and result.service not in self._created[result.host]:
            made = self._create("services", result.host, result.service, self._service_attrs()) or made
        if made and self._downtimes is not None:  # in its window's downtime before its first result
            self._downtimes.cover(result.host, self._created[result.host])
        return True

    def lost(self, result: CheckResult) -> None:
        """Icinga no longer has `result`'s object (deleted behind our back): it is made again next time."""
        assert self._created is not None
        if result.service:
            made = self._created.get(result.host)
            if made is not None:
                self._created[result.host] = self._sets.share(made - {result.service})
        else:
            self._created.pop(result.host, None)
            self._packaged.pop(result.host, None)  # the package is gone too, or a stage would clash

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
