"""One robot's diagnostics read straight from its ROS 1 master, for `check_ros_diagnostics --ros-master`.

It asks the master who publishes the topic (getSystemState and lookupNode: it registers nothing, so
a killed check leaves nothing behind on the robot), connects to every publisher at once over TCPROS,
and takes the first message that arrives. That message goes through a fleet model and the JSON API's
`robot_document`, so the check judges exactly what the exporter would serve for the robot.
"""

from __future__ import annotations

import contextlib
import queue
import socket
import threading
import time
from typing import Any

from overseer.codec import DecodeError
from overseer.codec.ros1 import decode_diagnostic_array
from overseer.fleet.documents import robot_document
from overseer.messages import DiagnosticArray
from overseer.model import FleetLimits, FleetModel
from overseer.sources.ros1.tcpros import TcprosError, read_frame, subscribe
from overseer.sources.ros1.xmlrpc import CALL_TIMEOUT_SECONDS, RosApiError, request_topic, topic_publishers

# The ROS 1 source's transport label; overseer.sources.ros1 is not imported for it because it
# loads the slave API server, which would double the check's start-up time.
TRANSPORT = "ros1"
DEFAULT_CALLER_ID = "/check_ros_diagnostics"
POLL_INTERVAL_SECONDS = 0.5


class Ros1DirectError(Exception):
    """The direct read failed; the message is one line for the check's UNKNOWN status."""


class MasterUnreachableError(Ros1DirectError):
    """The robot's master did not answer (or answered with an error)."""


class NoPublisherError(Ros1DirectError):
    """Nothing published the topic within the timeout."""


class MessageTimeoutError(Ros1DirectError):
    """Publishers were listed, but no message came from them within the timeout."""


def read_robot_document(
    master_uri: str,
    robot: str,
    timeout: float,
    topic: str = "diagnostics_agg",
    caller_id: str = DEFAULT_CALLER_ID,
    limits: FleetLimits | None = None,
) -> dict[str, Any]:
    """The API document of `robot` (named so) from the first message on `topic` within `timeout` seconds."""
    deadline = time.monotonic() + timeout
    topic_name = "/" + topic
    arrivals: queue.Queue[tuple[str, DiagnosticArray | str]] = queue.Queue()
    attempts: dict[str, _Attempt] = {}
    last_error = ""
    next_poll = 0.0
    try:
        while (now := time.monotonic()) < deadline:
            if now >= next_poll:  # the master is asked at most once per interval, whatever fails
                next_poll = now + POLL_INTERVAL_SECONDS
                try:
                    publishers = topic_publishers(
                        master_uri, caller_id, topic_name, min(deadline - now, CALL_TIMEOUT_SECONDS)
                    )
                except RosApiError as error:
                    if time.monotonic() >= deadline:
                        break  # a call cut short by the deadline: the outcome is the timeout's
                    raise MasterUnreachableError(f"ROS master unreachable at {master_uri}: {error}") from None
                for uri in publishers:
                    if uri not in attempts or not attempts[uri].alive:
                        attempts[uri] = _Attempt(uri, caller_id, topic_name, deadline, arrivals)
            try:
                uri, result = arrivals.get(timeout=max(0.0, min(next_poll, deadline) - time.monotonic()))
            except queue.Empty:
                continue
            if isinstance(result, DiagnosticArray):
                return _document(robot, result, topic_name, limits)
            last_error = f"{uri}: {result}"
    finally:
        for attempt in attempts.values():
            attempt.cancel()
    if not attempts:
        raise NoPublisherError(
            f"no publisher of {topic_name} at ROS master {master_uri} within {timeout:g} s"
        )
    suffix = f" (last error: {last_error})" if last_error else ""
    raise MessageTimeoutError(f"timeout: no message on {topic_name} within {timeout:g} s{suffix}")


def _document(robot: str, array: DiagnosticArray, topic: str, limits: FleetLimits | None) -> dict[str, Any]:
    model = FleetModel(limits)
    model.apply(robot, array, TRANSPORT, topic)
    snapshot = model.snapshot()
    state = snapshot.find(robot)
    assert state is not None  # a fresh model keeps its first robot
    return {**robot_document(snapshot, state), "maintenance": None}  # windows are the exporter's


class _Attempt:
    """One publisher, read in a daemon thread: its first message or its error goes to `arrivals`."""

    def __init__(
        self,
        uri: str,
        caller_id: str,
        topic: str,
        deadline: float,
        arrivals: queue.Queue[tuple[str, DiagnosticArray | str]],
    ) -> None:
        self._uri = uri
        self._caller_id = caller_id
        self._topic = topic
        self._deadline = deadline
        self._arrivals = arrivals
        self._lock = threading.Lock()
        self._sock: socket.socket | None = None
        self._cancelled = False
        self._thread = threading.Thread(target=self._run, name="ros1-direct", daemon=True)
        self._thread.start()

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def cancel(self) -> None:
        with self._lock:
            self._cancelled = True
            if self._sock is not None:
                with contextlib.suppress(OSError):
                    self._sock.shutdown(socket.SHUT_RDWR)

    def _run(self) -> None:
        try:
            self._arrivals.put((self._uri, self._read()))
        except DecodeError as error:
            self._arrivals.put((self._uri, f"undecodable message: {error}"))
        except (RosApiError, TcprosError) as error:
            if time.monotonic() < self._deadline:  # past it, the error is the timeout's, already reported
                self._arrivals.put((self._uri, str(error)))
        finally:
            with self._lock:
                if self._sock is not None:
                    self._sock.close()

    def _read(self) -> DiagnosticArray:
        host, port = request_topic(self._uri, self._caller_id, self._topic, self._remaining())
        sock = subscribe(host, port, self._caller_id, self._topic, self._remaining())
        with self._lock:
            self._sock = sock
            if self._cancelled:
                raise TcprosError("cancelled", "cancelled")
        sock.settimeout(self._remaining(cap=False))
        return decode_diagnostic_array(read_frame(sock))

    def _remaining(self, cap: bool = True) -> float:
        remaining = self._deadline - time.monotonic()
        if remaining <= 0:
            raise TcprosError("idle_timeout", "timed out")
        return min(remaining, CALL_TIMEOUT_SECONDS) if cap else remaining
