"""The ROS 1 transport: XML-RPC to each robot's master, TCPROS to its diagnostics publishers.

No rospy: the standard library speaks both. For each robot one thread registers us as a subscriber
of the robot's topic every `poll_interval`. The answer lists the publishers, so that one call is
both the poll that follows them when the master cannot reach our slave API and the re-registration
a restarted master needs; the master's `publisherUpdate` calls follow changes sooner. Each publisher
gets a thread that connects over TCPROS, decodes every frame into the fleet model and, after any
failure, reconnects with exponential backoff. Nothing is fatal: failures are counted and retried.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading
import time
from typing import Any

from overseer.codec import DecodeError
from overseer.codec.ros1 import MESSAGE_TYPE, WIRE_FORMAT
from overseer.config.ros1 import Ros1Config, Ros1Robot
from overseer.ingest.payload import PayloadIngest
from overseer.model import FleetModel
from overseer.sources.ros1.slave import SlaveApi
from overseer.sources.ros1.tcpros import TcprosError, read_frame, subscribe
from overseer.sources.ros1.xmlrpc import (
    CALL_TIMEOUT_SECONDS,
    RosApiError,
    register_subscriber,
    request_topic,
    unregister_subscriber,
)

log = logging.getLogger(__name__)

TRANSPORT = "ros1"
UNREGISTER_TIMEOUT_SECONDS = 1.0
STOP_TIMEOUT_SECONDS = 5.0
# Aggregators publish at 1 Hz, so only long silence means a dead connection rather than a quiet one.
MIN_IDLE_TIMEOUT_SECONDS = 30.0
IDLE_TIMEOUT_ROBOT_TIMEOUTS = 10
# A publisher that fails over and over (say, one that garbles every message) warns once per interval.
WARNING_INTERVAL_SECONDS = 60.0


class ErrorCounter:
    """Connection errors by reason, counted in the fleet model (overseer_source_errors_total)."""

    def __init__(self, model: FleetModel) -> None:
        """Count into `model`."""
        self._model = model

    def add(self, reason: str) -> None:
        """Count one error."""
        self._model.count_source_error(TRANSPORT, reason)

    def counts(self) -> dict[str, int]:
        """The counts so far, by reason."""
        errors = self._model.snapshot().source_errors
        return {reason: count for (transport, reason), count in errors.items() if transport == TRANSPORT}


class Backoff:
    """Delays that double from `minimum` up to `maximum` until `reset`."""

    def __init__(self, minimum: float, maximum: float) -> None:
        """Start at `minimum`."""
        self._minimum = minimum
        self._maximum = maximum
        self._next = minimum

    def next(self) -> float:
        """The delay to wait now."""
        delay = self._next
        self._next = min(delay * 2, self._maximum)
        return delay

    def reset(self) -> None:
        """Start again from `minimum`."""
        self._next = self._minimum


class Ros1Source:
    """Follows the diagnostics of every configured ROS 1 robot."""

    transport = TRANSPORT

    def __init__(self, config: Ros1Config, model: FleetModel) -> None:
        """Prepare to feed `model` from the robots in `config`; nothing connects until `start`."""
        self._config = config
        self._model = model
        self._errors = ErrorCounter(model)
        self._robots: list[_RobotLink] = []

    def start(self) -> None:
        """Make every robot known (down until it speaks) and start following it in the background."""
        idle_timeout = max(
            MIN_IDLE_TIMEOUT_SECONDS, IDLE_TIMEOUT_ROBOT_TIMEOUTS * self._model.limits.robot_timeout
        )
        for robot in self._config.robots:
            if not self._model.register(robot.name, TRANSPORT):
                log.warning("robot cap reached; not following ROS 1 robot %s", robot.name)
                continue
            link = _RobotLink(robot, self._config, self._model, self._errors, idle_timeout)
            link.start()
            self._robots.append(link)

    def stop(self) -> None:
        """Close every connection, unregister from the masters (best effort) and join the threads."""
        deadline = time.monotonic() + STOP_TIMEOUT_SECONDS
        for link in self._robots:
            link.stop()
        for link in self._robots:
            link.join(deadline)
        self._robots.clear()

    def error_counts(self) -> dict[str, int]:
        """Master and connection errors so far by reason (decode errors are the model's message counts).

        Reasons: master_unreachable, master_error, publisher_unreachable, publisher_error,
        handshake_error, frame_too_large, connection_lost, idle_timeout, shutdown_requested.
        """
        return self._errors.counts()


class _RobotLink:
    """One robot: its registration with the master, its slave API and its publisher connections."""

    def __init__(
        self,
        robot: Ros1Robot,
        config: Ros1Config,
        model: FleetModel,
        errors: ErrorCounter,
        idle_timeout: float,
    ) -> None:
        self.robot = robot
        self.topic = "/" + robot.topic
        self.config = config
        self.model = model
        self.errors = errors
        self.idle_timeout = idle_timeout
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._publishers: dict[str, _PublisherLink] = {}
        self._retired: list[_PublisherLink] = []
        self._caller_api: str | None = None
        self._slave = SlaveApi(
            config.caller_id,
            robot.master_uri,
            self.topic,
            MESSAGE_TYPE,
            config.advertise_host,
            on_publishers=self._follow,
            bus_info=self._bus_info,
            on_shutdown=self._on_shutdown,
        )
        self._thread = threading.Thread(target=self._run, name=f"ros1-{robot.name}", daemon=True)

    def start(self) -> None:
        self._slave.start()
        self._thread.start()

    def stop(self) -> None:
        """Signal the threads and close the sockets; the registration thread unregisters on its way out."""
        with self._lock:
            self._stop.set()
            links = list(self._publishers.values())
        for link in links:
            link.stop()

    def join(self, deadline: float) -> None:
        self._thread.join(max(0.0, deadline - time.monotonic()))
        with self._lock:
            links = [*self._publishers.values(), *self._retired]
        for link in links:
            link.join(max(0.0, deadline - time.monotonic()))

    def _run(self) -> None:
        backoff = Backoff(self.config.reconnect_min, self.config.reconnect_max)
        registered = False
        failing = False
        while not self._stop.is_set():
            try:
                self._caller_api = self._slave.uri()
                publishers = register_subscriber(
                    self.robot.master_uri,
                    self.config.caller_id,
                    self.topic,
                    MESSAGE_TYPE,
                    self._caller_api,
                    CALL_TIMEOUT_SECONDS,
                )
            except (RosApiError, OSError, UnicodeError) as error:  # the last two from resolving our address
                unreachable = not isinstance(error, RosApiError) or error.unreachable
                self.errors.add("master_unreachable" if unreachable else "master_error")
                if not failing:
                    log.warning(
                        "robot %s: ROS master %s: %s; retrying", self.robot.name, self.robot.master_uri, error
                    )
                failing = True
                self._stop.wait(backoff.next())
                continue
            if failing or not registered:
                log.info(
                    "robot %s: subscribed to %s at ROS master %s as %s",
                    self.robot.name,
                    self.topic,
                    self.robot.master_uri,
                    self._caller_api,
                )
            registered, failing = True, False
            backoff.reset()
            self._follow(publishers)
            self._stop.wait(self.config.poll_interval)
        self._close(registered)

    def _follow(self, publishers: list[str]) -> None:
        """Connect to new publishers and drop the ones that left."""
        with self._lock:
            if self._stop.is_set():
                return
            self._retired = [link for link in self._retired if link.alive]
            for uri in [uri for uri in self._publishers if uri not in publishers]:
                log.info("robot %s: publisher %s left %s", self.robot.name, uri, self.topic)
                link = self._publishers.pop(uri)
                link.stop()
                self._retired.append(link)
            for uri in publishers:
                if uri not in self._publishers or not self._publishers[uri].alive:
                    link = _PublisherLink(self, uri)
                    self._publishers[uri] = link
                    link.start()

    def ingest_for(self, publisher: str) -> PayloadIngest:
        """The ingest of one publisher's feed of the robot's topic: each node sends its own statuses."""
        return PayloadIngest(
            self.model, self.robot.name, TRANSPORT, self.topic, WIRE_FORMAT, f"{self.topic}@{publisher}"
        )

    def _close(self, registered: bool) -> None:
        if registered and self._caller_api is not None:
            try:
                unregister_subscriber(
                    self.robot.master_uri,
                    self.config.caller_id,
                    self.topic,
                    self._caller_api,
                    UNREGISTER_TIMEOUT_SECONDS,
                )
            except RosApiError as error:
                log.debug("robot %s: could not unregister: %s", self.robot.name, error)
        self._slave.stop()

    def _bus_info(self) -> list[list[Any]]:
        with self._lock:
            links = list(self._publishers.values())
        return [
            [number, link.uri, "i", "TCPROS", self.topic, link.connected]
            for number, link in enumerate(links, 1)
        ]

    def _on_shutdown(self, reason: str) -> None:
        self.errors.add("shutdown_requested")
        log.warning(
            "robot %s: asked to shut down (%s); is another node using caller id %s? Staying subscribed",
            self.robot.name,
            reason,
            self.config.caller_id,
        )


class _PublisherLink:
    """One publisher of a robot's topic: connect, receive frames into the model, reconnect after failures."""

    def __init__(self, robot: _RobotLink, uri: str) -> None:
        self.robot = robot
        self.uri = uri
        self._ingest = robot.ingest_for(uri)  # a payload like its last one only refreshes its statuses
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._sock: socket.socket | None = None
        self._announce = True  # log the next connection at info: the first one, or one after a warning
        self._thread = threading.Thread(
            target=self._run, name=f"ros1-{robot.robot.name}-publisher", daemon=True
        )

    @property
    def connected(self) -> bool:
        with self._lock:
            return self._sock is not None

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        """Make the thread leave: a blocked read returns as soon as its socket is shut down."""
        with self._lock:
            self._stop.set()
            if self._sock is not None:
                with contextlib.suppress(OSError):  # already disconnected
                    self._sock.shutdown(socket.SHUT_RDWR)

    def join(self, timeout: float) -> None:
        self._thread.join(timeout)

    def _run(self) -> None:
        robot = self.robot
        backoff = Backoff(robot.config.reconnect_min, robot.config.reconnect_max)
        next_warning = 0.0
        while not self._stop.is_set():
            reason, message = self._receive(backoff)
            if self._stop.is_set():
                break
            if reason != "decode_error":
                robot.errors.add(reason)
            now = time.monotonic()
            if now >= next_warning:
                log.warning(
                    "robot %s: publisher %s: %s; reconnecting (failures logged at debug for %gs)",
                    robot.robot.name,
                    self.uri,
                    message,
                    WARNING_INTERVAL_SECONDS,
                )
                next_warning = now + WARNING_INTERVAL_SECONDS
                self._announce = True
            else:
                log.debug("robot %s: publisher %s: %s", robot.robot.name, self.uri, message)
            self._stop.wait(backoff.next())

    def _receive(self, backoff: Backoff) -> tuple[str, str]:
        """Feed the model until something fails; returns the failure's reason and message."""
        robot = self.robot
        caller_id, topic = robot.config.caller_id, robot.topic
        try:
            host, port = request_topic(self.uri, caller_id, topic, CALL_TIMEOUT_SECONDS)
            sock = subscribe(host, port, caller_id, topic, CALL_TIMEOUT_SECONDS)
            with self._lock:
                self._sock = sock
                if self._stop.is_set():
                    return "stopped", "stopped"
            sock.settimeout(robot.idle_timeout)
            log.log(
                logging.INFO if self._announce else logging.DEBUG,
                "robot %s: receiving %s from %s (%s:%d)",
                robot.robot.name,
                topic,
                self.uri,
                host,
                port,
            )
            self._announce = False
            while True:
                self._ingest(read_frame(sock))
                backoff.reset()
        except DecodeError as error:  # already counted as decode_error by the ingest
            return "decode_error", f"undecodable message: {error}"
        except RosApiError as error:
            return ("publisher_unreachable" if error.unreachable else "publisher_error"), str(error)
        except TcprosError as error:
            return error.reason, str(error)
        finally:
            with self._lock:
                if self._sock is not None:
                    self._sock.close()
                    self._sock = None
