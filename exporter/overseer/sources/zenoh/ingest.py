"""What the Zenoh transport does with each sample and each liveliness token it hears, apart from the session.

A sample is its key, its attachment and its payload; a token is its key and whether it came or went. The
same ingest is fed by the exporter's own session (`source.py`, one process) or, with several ingest
workers, by the exporter's relay through a pipe and shared memory (`relayed.py`): it never sees Zenoh's
objects.

A sample of an un-namespaced topic (diagnostic_updater publishes on `/diagnostics` whatever its node's
namespace) belongs to the robot its publisher's node names: the sample's attachment carries the
publisher's GID, and the publisher's liveliness token, whose hash that GID is, its node's namespace
(`robot_naming.py`). Each publisher is a feed of its robot.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field

from overseer.codec import DecodeError, cdr
from overseer.config.zenoh import ZenohConfig
from overseer.ingest.payload import PayloadIngest
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.sources.reattribution import MovedFeeds
from overseer.sources.robot_naming import RobotNaming
from overseer.sources.topic_names import AGGREGATED, RAW
from overseer.sources.zenoh.keys import (
    DIAGNOSTIC_ARRAY_HASH,
    RMW_ZENOH,
    DiagnosticsKey,
    RejectedKey,
    attachment_fields,
    parse_data_key,
)
from overseer.sources.zenoh.relay_items import DROPPED, ERROR, SAMPLE, TOKEN, Item
from overseer.sources.zenoh.sequence_gaps import SequenceGaps
from overseer.sources.zenoh.tokens import token_subject

log = logging.getLogger(__name__)

TRANSPORT = "zenoh"
TICK_SECONDS = 0.5  # how often `tick` is called: a publisher held for its token waits no longer than this
PRUNE_INTERVAL_SECONDS = 60.0
ATTRIBUTION_GRACE_SECONDS = 3.0  # a publisher with no token by then (another rmw, a bridge): the domain's
MAX_TOKENS_PER_ROBOT = 64
MAX_PENDING_PUBLISHERS = 10_000
MAX_PENDING_SAMPLES = 16  # per publisher, while its robot is not known yet
MAX_KNOWN_KEYS = 100_000  # keys remembered, ours or another shard's (bounded against key floods)


# What a key says: its topic and the robot its namespace names (None: its publisher's node decides), or
# (None, None) for a key of another shard's robot or of no robot's diagnostics.
_KeyReading = tuple[DiagnosticsKey | None, str | None]
_NOT_OURS: _KeyReading = (None, None)


@dataclass
class _Unattributed:
    """Samples of an un-namespaced topic from a publisher whose token has not arrived yet."""

    parsed: DiagnosticsKey
    seen_at: float
    samples: list[bytes] = field(default_factory=list)


class ZenohIngest:
    """Feeds the fleet model from Zenoh samples and publisher liveliness tokens of the robots `shard` owns.

    `counts_shared_errors`: whether this ingest counts what every ingest of the exporter would see alike
    (an unreachable router, a key that is no robot's); with the exporter's own session, only the first
    worker's does.
    """

    def __init__(
        self,
        config: ZenohConfig,
        model: FleetModel,
        shard: Shard,
        naming: RobotNaming,
        counts_shared_errors: bool = True,
    ) -> None:
        """Feed `model` with the samples handed to `on_sample` and the tokens handed to `on_token`."""
        self._config = config
        self._model = model
        self._shard = shard
        self._naming = naming
        self.counts_shared_errors = counts_shared_errors
        self._lock = threading.Lock()
        # (robot, kind, publisher GID or b"") → its feed's ingest, None when not followed
        self._ingests: dict[tuple[str, str, bytes], PayloadIngest | None] = {}
        # robot → its feeds in `_ingests`: a new feed looks at its robot's, not at the whole fleet's
        self._feeds_of: dict[str, list[tuple[str, str, bytes]]] = {}
        # A key is read once, not at every sample (10,000 a second in a large fleet).
        self._keys: dict[str, _KeyReading] = {}
        self._tokens: dict[str, set[str]] = {}  # robot → live tokens of its diagnostics publishers
        self._publishers: dict[bytes, str] = {}  # GID → robot, from the publishers' tokens
        self._gaps = SequenceGaps()  # by publisher GID: what each sent and this exporter never heard
        self._unattributed: dict[bytes, _Unattributed] = {}
        # GID → its key, of a publisher taken for the domain's robot (this ingest's) before any token
        self._by_domain: dict[bytes, DiagnosticsKey] = {}
        self._moved = MovedFeeds(model)
        self._pruned = time.monotonic()

    def count_source_error(self, reason: str) -> None:
        """Count one error every ingest of the exporter would see alike, if this one counts them."""
        if self.counts_shared_errors:
            self._model.count_source_error(TRANSPORT, reason)

    def on_sample(self, key: str, attachment: bytes | None, payload: bytes) -> None:
        """Apply one sample; never raises (what is wrong with it is counted)."""
        try:
            self._apply(key, attachment, payload)
        except DecodeError as error:  # already counted by the ingest
            log.debug("undecodable sample on %s: %s", key, error)
        except Exception:  # a sample must never end the thread that hands them over
            log.exception("failed to process diagnostics from %s", key)

    def on_items(self, items: list[Item]) -> int:
        """Apply a batch of what the session heard (`relay_items.py`), in order; returns its samples."""
        samples = 0
        for item in items:
            kind = item[0]
            if kind == SAMPLE:
                samples += 1
                self.on_sample(item[1], item[2], item[3])
            elif kind == TOKEN:
                self.on_token(item[1], item[2])
            elif kind == DROPPED:
                self.dropped(item[1], item[2])
            elif kind == ERROR:
                self.count_source_error(item[1])
        return samples

    def dropped(self, count: int, heard: list[tuple[bytes, int]]) -> None:
        """`count` samples were dropped before they reached this ingest (a full queue); counted as such.

        `heard` are their publishers' GIDs with the highest sequence number dropped of each: they are
        not counted lost as well.
        """
        self._model.count_message(TRANSPORT, "dropped", count)
        for gid, sequence in heard:
            self._gaps.heard(gid, sequence)

    def dropped_samples(self, samples: list[tuple[str, bytes | None]]) -> None:
        """Samples (key, attachment) dropped before they reached this ingest (a full queue), in order.

        Those of its own robots (or of a robot not known yet) are counted dropped, and their numbers
        heard: they are not counted lost as well.
        """
        ours = [attachment for key, attachment in samples if self._is_ours(key)]
        if ours:
            numbers = [attachment_fields(attachment) for attachment in ours]
            self.dropped(len(ours), [(gid, n) for gid, n in numbers if gid is not None and n is not None])

    def _is_ours(self, key: str) -> bool:
        """Whether `key` is a robot's diagnostics this ingest follows (or a robot not known yet)."""
        parsed, _ = self._keys.get(key) or self._read_key(key)
        return parsed is not None

    def _apply(self, key: str, attachment: bytes | None, payload: bytes) -> None:
        parsed, robot = self._keys.get(key) or self._read_key(key)
        if parsed is None:
            return  # another shard's robot, or not a robot's diagnostics
        if parsed.key_format == RMW_ZENOH and parsed.type_hash != DIAGNOSTIC_ARRAY_HASH:
            # Another revision of the message: read anyway (the codec checks every byte), but say so.
            self._model.count_source_error(TRANSPORT, "type_hash_mismatch")
        publisher, sequence = attachment_fields(attachment)
        gid = publisher or b""
        if robot is None:
            robot = self._publishers.get(gid) if gid else self._naming.unnamespaced_robot
            if robot is None:
                self._hold(gid, parsed, payload)
                return
            if not self._shard.owns(robot):
                return
        ingest = self._ingest_for(robot, parsed, gid)
        if ingest is not None:
            if sequence is not None:
                self._count_lost(robot, parsed, gid, sequence)
            ingest(payload)

    def _read_key(self, key: str) -> _KeyReading:
        """What a key says (remembered, up to a bound); one that is no robot's is counted each time."""
        try:
            parsed = parse_data_key(key, self._config.domain)
        except RejectedKey as rejected:
            self.count_source_error(str(rejected))
            log.debug("ignoring Zenoh key %r: %s", key, rejected)
            return _NOT_OURS
        robot = self._naming.of_topic(parsed.namespace)
        reading = _NOT_OURS if robot is not None and not self._shard.owns(robot) else (parsed, robot)
        if len(self._keys) < MAX_KNOWN_KEYS:
            self._keys[key] = reading
        return reading

    def _count_lost(self, robot: str, parsed: DiagnosticsKey, gid: bytes, sequence: int) -> None:
        """Count the samples a publisher sent before `sequence` and this exporter never heard."""
        missed = self._gaps.missed(gid, sequence)
        if missed:
            self._model.count_message(TRANSPORT, "lost", missed)
            lost = self._gaps.lost(gid)
            before = lost - missed
            if not before or len(str(lost)) > len(str(before)):  # its first loss, then at each power of ten
                log.warning(
                    "%d samples of %s's %s (publisher %s) never heard so far: the router or the link "
                    "dropped them, or this exporter could not keep up",
                    lost,
                    robot,
                    parsed.topic,
                    gid.hex(),
                )

    def _hold(self, gid: bytes, parsed: DiagnosticsKey, payload: bytes) -> None:
        """Keep a sample of a publisher whose token (whose node) is not known yet."""
        with self._lock:
            waiting = self._unattributed.get(gid)
            if waiting is None:
                if len(self._unattributed) >= MAX_PENDING_PUBLISHERS:
                    return
                waiting = self._unattributed[gid] = _Unattributed(parsed, time.monotonic())
            if len(waiting.samples) < MAX_PENDING_SAMPLES:
                waiting.samples.append(payload)
            else:
                waiting.samples[-1] = payload  # the newest says the most

    def _release(self, gid: bytes, robot: str) -> None:
        """Hand a publisher's held samples to its robot, now that its robot is known."""
        with self._lock:
            waiting = self._unattributed.pop(gid, None)
        if waiting is None or not self._shard.owns(robot):
            return
        ingest = self._ingest_for(robot, waiting.parsed, gid)
        if ingest is None:
            return
        for payload in waiting.samples:
            try:
                ingest(payload)
            except DecodeError:  # counted by the ingest
                continue

    def tick(self) -> None:
        """The upkeep done every fraction of a second: late attributions, and now and then a prune."""
        self._moved.forget(self._follows)
        self._attribute_late()
        if time.monotonic() - self._pruned >= PRUNE_INTERVAL_SECONDS:
            self._pruned = time.monotonic()
            self._prune()

    def _attribute_late(self) -> None:
        """Publishers heard with no token within the grace belong to the domain's robot."""
        now = time.monotonic()
        with self._lock:
            waiting = self._unattributed.items()
            late = [
                (gid, held.parsed) for gid, held in waiting if now - held.seen_at >= ATTRIBUTION_GRACE_SECONDS
            ]
        domain_robot = self._naming.unnamespaced_robot
        for gid, parsed in late:
            with self._lock:
                robot = self._publishers.get(gid)
                if robot is None:  # its token did not come meanwhile
                    robot = self._publishers[gid] = domain_robot
                    if self._shard.owns(domain_robot):
                        self._by_domain[gid] = parsed
            self._release(gid, robot)

    def _follows(self, robot: str) -> bool:
        """Whether this ingest hears `robot` through some feed or token."""
        return robot in self._feeds_of or robot in self._tokens

    def _move(self, old: str, parsed: DiagnosticsKey, gid: bytes, robot: str) -> None:
        """A publisher taken for the domain's robot is `robot`'s: the domain's robot leaves its feed."""
        feed = (old, parsed.kind, gid)
        with self._lock:
            ingest = self._ingests.pop(feed, None)
            feeds = self._feeds_of.get(old, [])
            if feed in feeds:
                feeds.remove(feed)
                if not feeds:
                    del self._feeds_of[old]
        if ingest is not None:
            self._moved.moved(old, f"{parsed.topic}@{gid.hex()}")
        log.info("Zenoh publisher %s of %s: a node of robot %s, not %s", gid.hex(), parsed.topic, robot, old)

    def _ingest_for(self, robot: str, parsed: DiagnosticsKey, gid: bytes) -> PayloadIngest | None:
        """The ingest of a publisher's feed; None when it is not followed (raw beside aggregated, cap)."""
        feed = (robot, parsed.kind, gid)
        ingest = self._ingests.get(feed)
        if ingest is not None or feed in self._ingests:
            return ingest
        with self._lock:
            if feed in self._ingests:
                return self._ingests[feed]
            if gid and not parsed.namespace and self._publishers.get(gid, robot) != robot:
                return None  # its token moved it to another robot since this sample read it
            feeds = self._feeds_of.get(robot, [])
            if parsed.kind == RAW and any(kind == AGGREGATED for _, kind, _ in feeds):
                self._add_feed(feed, None)  # a robot publishing both is read from diagnostics_agg only
                return None
            if not self._model.register(robot, TRANSPORT):
                self._model.count_message(TRANSPORT, "dropped")
                return None
            if parsed.kind == AGGREGATED:
                for key in [key for key in feeds if key[1] == RAW]:
                    self._ingests[key] = None
                    self._model.forget_topic(robot, parsed.topic[: -len(AGGREGATED)] + RAW)
            name = f"{parsed.topic}@{gid.hex()}" if gid else parsed.topic
            ingest = PayloadIngest(self._model, robot, TRANSPORT, parsed.topic, cdr.WIRE_FORMAT, name)
            self._add_feed(feed, ingest)
            log.info("following robot %s over Zenoh (%s, %s)", robot, parsed.topic, parsed.key_format)
            return ingest

    def _add_feed(self, feed: tuple[str, str, bytes], ingest: PayloadIngest | None) -> None:
        """Remember a feed's ingest (None: not followed), under `_lock`."""
        self._ingests[feed] = ingest
        self._feeds_of.setdefault(feed[0], []).append(feed)

    def on_token(self, key: str, alive: bool) -> None:
        """A diagnostics publisher's token came (`alive`) or went; never raises."""
        try:
            self._apply_token(key, alive)
        except Exception:  # a token must never end the thread that hands them over
            log.exception("failed to process liveliness token %s", key)

    def _apply_token(self, key: str, alive: bool) -> None:
        subject = token_subject(key, self._config, self._naming)
        if subject is None:
            return
        robot, gid = subject.robot, subject.gid
        if robot is None:
            self.count_source_error("invalid_namespace")  # every worker hears every token
            return
        if gid and alive:
            with self._lock:
                old = self._publishers.get(gid)
                self._publishers[gid] = robot
                by_domain = self._by_domain.pop(gid, None)
            if by_domain is not None and old is not None and old != robot:
                self._move(old, by_domain, gid, robot)
            self._release(gid, robot)
        if not self._shard.owns(robot):
            return
        with self._lock:
            tokens = self._tokens.get(robot)
            if alive:
                if not self._model.register(robot, TRANSPORT):
                    return
                tokens = self._tokens.setdefault(robot, set())
                if len(tokens) < MAX_TOKENS_PER_ROBOT:
                    tokens.add(key)
            elif tokens is not None:
                tokens.discard(key)
                if not tokens:
                    del self._tokens[robot]
                    self._model.publisher_left(robot)
            else:
                return
        log.info("diagnostics publisher of %s %s", robot, "appeared" if alive else "went away")

    def _prune(self) -> None:
        """Forget the ingests, tokens and publishers of robots the model has forgotten (expired)."""
        known = {robot.name for robot in self._model.snapshot().robots}
        with self._lock:
            for robot in [robot for robot in self._feeds_of if robot not in known]:
                for feed in self._feeds_of.pop(robot):
                    del self._ingests[feed]
                    self._gaps.forget(feed[2])
            for robot in [robot for robot in self._tokens if robot not in known]:
                del self._tokens[robot]
            owns = self._shard.owns
            for gid in [gid for gid, robot in self._publishers.items() if robot not in known and owns(robot)]:
                del self._publishers[gid]
            for gid in [gid for gid in self._by_domain if gid not in self._publishers]:
                del self._by_domain[gid]
