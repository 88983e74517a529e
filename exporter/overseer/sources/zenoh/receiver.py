"""The exporter's Zenoh session: every robot's diagnostics and publisher tokens, handed on as plain values.

One session (a client of the configured routers by default) subscribes to every robot's diagnostics keys
with wildcards, so robots that start later, or were built against another revision of the message
(another type hash), are heard with no restart, and to the liveliness tokens of their publishers
(rmw_zenoh's, and zenoh-bridge-ros2dds's for the routes it serves). A sample goes on as its key,
attachment and payload; a token as its key and whether it came or went. Routers that are not up yet are
retried until they are.

The bridge's tokens are subscribed to once a sample in the bridge's key format is heard, with the
tokens' history, so none is missed: a router serves every subscription of tokens as it serves another
subscriber, and a fleet of 10,000 rmw_zenoh robots starting at once lost 1.3-3.3 times as many updates
at the router while the exporter held both from the start (bench/README.md, 2026-11-29).

The samples and the tokens queue in channels that Zenoh fills without Python's interpreter lock, and a
thread of ours drains each: a Python callback would hold Zenoh's receiving thread on the lock for every
sample or token, so a busy moment in Python would stall the link and the router would drop samples.
Given `on_dropped`, the samples' thread copies out everything waiting in Zenoh before each share of the
handler's work, and up to `zenoh.queue_length` copies wait for it (`paced_drain.drain_buffered`).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

import zenoh
from zenoh.handlers import FifoChannel

from overseer.config.zenoh import ZenohConfig
from overseer.sources.paced_drain import drain_buffered, drain_paced
from overseer.sources.zenoh.ingest import TICK_SECONDS
from overseer.sources.zenoh.keys import (
    BRIDGE,
    RMW_ZENOH,
    bridge_liveliness_subscription,
    data_subscriptions,
    liveliness_subscription,
)
from overseer.sources.zenoh.session import session_config

log = logging.getLogger(__name__)

RETRY_MIN_SECONDS = 0.5
RETRY_MAX_SECONDS = 10.0
MAX_WAITING_TOKENS = 200_000  # a fleet's tokens, heard at once (two a robot): beyond, Zenoh's thread waits

SampleHandler = Callable[[str, bytes | None, bytes], None]  # key, attachment, payload
TokenHandler = Callable[[str, bool], None]  # key, alive
DroppedSample = tuple[str, bytes | None]  # key, attachment
DroppedHandler = Callable[[list[DroppedSample]], None]  # samples dropped in a row, in order
_Copied = tuple[str, bytes | None, bytes]  # what `SampleHandler` is given


class ZenohReceiver:
    """Hands every diagnostics sample and publisher token of one Zenoh session to the given handlers.

    `on_unreachable` is called at each failed attempt to open the session; `tick` every `TICK_SECONDS`
    (the ingest's upkeep) while it is open; `on_dropped`, if given, with the samples beyond the
    samples' queue, where they came among the others. Handlers are called from the receiver's
    threads, samples from one thread per subscription, and must not raise.
    """

    def __init__(
        self,
        config: ZenohConfig,
        on_sample: SampleHandler,
        on_token: TokenHandler,
        on_unreachable: Callable[[], None],
        tick: Callable[[], None],
        on_dropped: DroppedHandler | None = None,
    ) -> None:
        """Prepare the session `config` describes; ConfigError at once if it is unusable."""
        self._config = config
        self._native = session_config(config)
        self._on_sample = on_sample
        self._on_token = on_token
        self._on_unreachable = on_unreachable
        self._tick = tick
        self._on_dropped = on_dropped
        self._lock = threading.Lock()
        self._session: zenoh.Session | None = None
        self._declared: list[zenoh.Subscriber[Any]] = []
        self.token_subscriptions: list[str] = []  # the key expressions of the tokens subscribed to
        self._bridge_heard = False  # a sample in the bridge's key format came: its tokens are wanted
        self.samples_heard = 0  # samples this session received
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Open the session in the background."""
        self._thread = threading.Thread(target=self._run, name="zenoh-session", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Undeclare everything and close the session."""
        self._stop.set()
        with self._lock:
            session, self._session = self._session, None
            declared, self._declared = self._declared, []
        for subscriber in declared:
            subscriber.undeclare()  # type: ignore[no-untyped-call]
        if session is not None:
            session.close()  # type: ignore[no-untyped-call]
        if self._thread is not None:
            self._thread.join(timeout=2)

    def _run(self) -> None:
        session = self._open()
        if session is None:
            return
        domain, formats = self._config.domain, self._config.key_formats
        # Declared without the lock held: `stop` may wait for it meanwhile.
        declared: list[zenoh.Subscriber[Any]] = []
        for key_format in dict.fromkeys(formats):  # each format once, however often it was given
            copy = self._bridged_copy if key_format == BRIDGE else self._copy
            for key in data_subscriptions(domain, (key_format,)):
                subscriber = session.declare_subscriber(key, FifoChannel(self._config.queue_length))
                declared.append(subscriber)
                if self._on_dropped is None:
                    self._start_drain(subscriber.handler, self._handing_on(copy), "zenoh-data")
                else:
                    self._start_buffered_drain(subscriber.handler, copy)
        if RMW_ZENOH in formats:
            declared.append(self._subscribe_tokens(session, liveliness_subscription(domain)))
        with self._lock:
            stopped = self._stop.is_set()
            if not stopped:
                self._session, self._declared = session, declared
        if stopped:
            session.close()  # type: ignore[no-untyped-call]
            return
        if self._bridge_heard:  # before the session was kept: its tokens could not be subscribed to then
            self._subscribe_bridge_tokens()
        log.info("Zenoh session %s open (%s)", session.zid(), self._native.get_json("mode"))
        while not self._stop.wait(TICK_SECONDS):
            self._tick()

    def _subscribe_tokens(self, session: zenoh.Session, key: str) -> zenoh.Subscriber[Any]:
        """Subscribe to the tokens matching `key`, those declared before included, drained by a thread."""
        # Tokens wait in a channel too: a callback would hold the link's receiving thread on the
        # interpreter lock for each of them (a fleet's 20,000 at once), and the router would drop the
        # samples that came meanwhile.
        liveliness = session.liveliness()
        subscriber = liveliness.declare_subscriber(key, FifoChannel(MAX_WAITING_TOKENS), history=True)
        self.token_subscriptions.append(key)
        self._start_drain(subscriber.handler, self._token, "zenoh-tokens")
        return subscriber

    def _subscribe_bridge_tokens(self) -> None:
        """Subscribe to zenoh-bridge-ros2dds's tokens, once, if the session is open and not stopping."""
        with self._lock:
            session = self._session
            key = bridge_liveliness_subscription()
            if session is None or key in self.token_subscriptions:
                return
            try:
                # Under the lock: `stop` undeclares what is declared, and takes the lock to do so.
                self._declared.append(self._subscribe_tokens(session, key))
            except Exception:  # called from a drain, which must go on: the next bridge's sample tries again
                self._bridge_heard = False
                log.exception("failed to subscribe to zenoh-bridge-ros2dds's tokens")

    def _bridged_copy(self, sample: zenoh.Sample) -> _Copied | None:
        """`_copy` for a sample in the bridge's key format: the first one subscribes to its tokens."""
        if not self._bridge_heard:
            self._bridge_heard = True
            self._subscribe_bridge_tokens()
        return self._copy(sample)

    def _open(self) -> zenoh.Session | None:
        delay = RETRY_MIN_SECONDS
        while not self._stop.is_set():
            try:
                return zenoh.open(self._native)
            except zenoh.ZError as error:
                self._on_unreachable()
                log.warning("cannot open the Zenoh session (retrying in %gs): %s", delay, error)
            self._stop.wait(delay)
            delay = min(delay * 2, RETRY_MAX_SECONDS)
        return None

    def _start_drain(self, channel: Any, handle: Callable[[zenoh.Sample], None], name: str) -> None:
        """Drain `channel` into `handle` on a thread of its own."""
        threading.Thread(target=self._drain, args=(channel, handle), name=name, daemon=True).start()

    def _drain(self, channel: Any, handle: Callable[[zenoh.Sample], None]) -> None:
        """Hand every sample of one subscription's channel on, in batches, until it is closed."""
        drain_paced(*_reads(channel), handle, self._stop.is_set)

    def _start_buffered_drain(self, channel: Any, copy: Callable[[zenoh.Sample], _Copied | None]) -> None:
        """Copy the samples out of `channel` (with `copy`) between shares of their handling, on a thread."""
        limit = self._config.queue_length
        handlers = (copy, self._hand_on, self._note, self._drop)
        arguments = (*_reads(channel), *handlers, self._stop.is_set, limit)
        threading.Thread(target=drain_buffered, args=arguments, name="zenoh-data", daemon=True).start()

    def _copy(self, sample: zenoh.Sample) -> _Copied | None:
        self.samples_heard += 1
        try:
            attachment = sample.attachment
            key = str(sample.key_expr)
            return key, None if attachment is None else attachment.to_bytes(), sample.payload.to_bytes()
        except Exception:  # the drain must go on
            log.exception("failed to read a sample")
            return None

    def _hand_on(self, copied: _Copied) -> None:
        try:
            self._on_sample(*copied)
        except Exception:  # the drain must go on
            log.exception("failed to hand on a sample of %s", copied[0])

    def _note(self, sample: zenoh.Sample) -> DroppedSample:
        """What the ingest needs of a sample it will not get: its key and its attachment (its number)."""
        self.samples_heard += 1
        try:
            attachment = sample.attachment
            return str(sample.key_expr), None if attachment is None else attachment.to_bytes()
        except Exception:  # the drain must go on
            log.exception("failed to read a sample")
            return "", None

    def _drop(self, samples: list[DroppedSample]) -> None:
        if self._on_dropped is None:
            return
        try:
            self._on_dropped(samples)
        except Exception:  # the drain must go on
            log.exception("failed to count %d dropped samples", len(samples))

    def _handing_on(self, copy: Callable[[zenoh.Sample], _Copied | None]) -> Callable[[zenoh.Sample], None]:
        """A drain's handler: each sample copied with `copy`, then handed on."""

        def handle(sample: zenoh.Sample) -> None:
            copied = copy(sample)
            if copied is not None:
                self._hand_on(copied)

        return handle

    def _token(self, sample: zenoh.Sample) -> None:
        try:
            self._on_token(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)
        except Exception:  # a callback from Zenoh's threads must never raise
            log.exception("failed to hand on liveliness token %s", sample.key_expr)


def _reads(channel: Any) -> tuple[Callable[[], zenoh.Sample | None], Callable[[], zenoh.Sample | None]]:
    """A channel's blocking and non-blocking reads, each None once the channel is closed."""

    def wait() -> zenoh.Sample | None:
        try:
            sample: zenoh.Sample = channel.recv()
        except zenoh.ZError:  # closed: the subscriber was undeclared
            return None
        return sample

    def poll() -> zenoh.Sample | None:
        try:
            sample: zenoh.Sample | None = channel.try_recv()
        except zenoh.ZError:
            return None
        return sample

    return wait, poll
