"""Real ROS 1 for tests: Debian's rosmaster, rospy publishers and genpy, and a fake TCPROS publisher.

The Debian programs run under /usr/bin/python3, never the project's venv. The fake publisher is a
hand-written node registered with a real master, for the bytes rospy never sends.
"""

from __future__ import annotations

import contextlib
import json
import signal
import socket
import struct
import subprocess
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xmlrpc.server import SimpleXMLRPCServer

from overseer.codec.ros1 import MD5SUM, MESSAGE_TYPE
from overseer.sources.ros1.tcpros import MAX_HEADER_BYTES, decode_header, encode_header, read_block
from overseer.sources.ros1.xmlrpc import RosApiError, ros_call
from testbed.paths import TESTBED
from testbed.ports import free_port
from testbed.processes import RunningProcess, spawn, wait_for

ROS_PYTHON = "/usr/bin/python3"
ROSMASTER = "/usr/bin/rosmaster"
SCRIPTS = TESTBED / "ros1"
PUBLISHER_SCRIPT = SCRIPTS / "diagnostics_publisher.py"
GENPY_SCRIPT = SCRIPTS / "genpy_messages.py"
TOPIC = "/diagnostics_agg"


def ros_env(master_uri: str, tmp_path: Path) -> dict[str, str]:
    """Environment for a ROS 1 process on loopback, logging under `tmp_path`."""
    return {"ROS_IP": "127.0.0.1", "ROS_MASTER_URI": master_uri, "ROS_HOME": str(tmp_path / "ros_home")}


@dataclass
class Master(RunningProcess):
    """A running `rosmaster --core` and its URI."""

    port: int

    @property
    def uri(self) -> str:
        """The master's XML-RPC URI."""
        return f"http://127.0.0.1:{self.port}/"

    def system_state(self) -> list[Any]:
        """[publishers, subscribers, services], each a list of [name, [nodes]]."""
        state: list[Any] = ros_call(self.uri, "getSystemState", "/test", timeout=5)
        return state

    def publishers(self, topic: str = TOPIC) -> list[str]:
        """The nodes the master lists as publishers of `topic`."""
        return next((nodes for name, nodes in self.system_state()[0] if name == topic), [])

    def subscribers(self, topic: str = TOPIC) -> list[str]:
        """The nodes the master lists as subscribers of `topic`."""
        return next((nodes for name, nodes in self.system_state()[1] if name == topic), [])


def start_master(tmp_path: Path, port: int | None = None) -> Master:
    """Start `rosmaster --core` on loopback (on `port`, default a free one) and wait until it answers."""
    port = port or free_port()
    uri = f"http://127.0.0.1:{port}/"
    args = [ROS_PYTHON, ROSMASTER, "--core", "-p", str(port)]
    log_path = tmp_path / f"rosmaster-{port}-{time.monotonic_ns()}.log"
    master = Master(spawn(args, log_path, ros_env(uri, tmp_path)), log_path, port)
    try:
        wait_for(lambda: _answers(master), 30, message=f"rosmaster on port {port}")
    except BaseException:
        master.stop()
        raise
    return master


def _answers(master: Master) -> bool:
    if master.process.poll() is not None:
        raise RuntimeError(f"rosmaster exited with {master.process.returncode}:\n{master.log()}")
    try:
        ros_call(master.uri, "getPid", "/test", timeout=1)
    except RosApiError:
        return False
    return True


@contextmanager
def running_master(tmp_path: Path, port: int | None = None) -> Iterator[Master]:
    """A ROS 1 master on loopback until the block ends."""
    master = start_master(tmp_path, port)
    try:
        yield master
    finally:
        master.stop()


def start_publisher(
    tmp_path: Path, master: Master, node: str, statuses: Sequence[str], rate: float = 2.0, topic: str = TOPIC
) -> RunningProcess:
    """Start testbed/ros1/diagnostics_publisher.py and wait until the master lists it on `topic`.

    Each status is LEVEL:NAME[:MESSAGE[:HARDWARE_ID[:KEY=VALUE,...]]], as the script takes them.
    """
    args = [ROS_PYTHON, str(PUBLISHER_SCRIPT), f"--node={node}", f"--rate={rate:g}", f"--topic={topic}"]
    args += [f"--status={status}" for status in statuses]
    log_path = tmp_path / f"publisher-{node}-{time.monotonic_ns()}.log"
    publisher = RunningProcess(spawn(args, log_path, ros_env(master.uri, tmp_path)), log_path)
    try:
        wait_for(
            lambda: _publishing(publisher, master, node, topic), 30, message=f"{node} publishing on {topic}"
        )
    except BaseException:
        publisher.stop()
        raise
    return publisher


def _publishing(publisher: RunningProcess, master: Master, node: str, topic: str) -> bool:
    if publisher.process.poll() is not None:
        raise RuntimeError(f"publisher {node} exited with {publisher.process.returncode}:\n{publisher.log()}")
    return f"/{node}" in master.publishers(topic)


@contextmanager
def running_publisher(
    tmp_path: Path, master: Master, node: str, statuses: Sequence[str], rate: float = 2.0, topic: str = TOPIC
) -> Iterator[RunningProcess]:
    """A rospy DiagnosticArray publisher until the block ends."""
    publisher = start_publisher(tmp_path, master, node, statuses, rate, topic)
    try:
        yield publisher
    finally:
        publisher.stop()


def kill(process: RunningProcess) -> None:
    """Kill with SIGKILL, as a crash or a power cut would: no unregistering from the master."""
    process.stop(signal.SIGKILL)


def genpy(mode: str, items: list[Any]) -> Any:
    """Run testbed/ros1/genpy_messages.py: 'serialize' messages to payloads, or 'deserialize' payloads."""
    done = subprocess.run(
        [ROS_PYTHON, str(GENPY_SCRIPT), mode],
        input=json.dumps(items),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    if mode == "serialize":
        return [bytes.fromhex(line) for line in done.stdout.split()]
    return json.loads(done.stdout)


def frame(payload: bytes) -> bytes:
    """A TCPROS frame: a true length prefix and the payload."""
    return struct.pack("<I", len(payload)) + payload


# A fake publisher's script: for the Nth connection (from 1), the raw bytes to send after the handshake,
# and pauses in seconds between them.
Script = Callable[[int], Iterable[bytes | float]]


class FakePublisher:
    """A hand-written ROS 1 publisher node registered with a real master, sending scripted bytes.

    Each connection gets the publisher's handshake reply (`reply_header`), then the chunks of
    `script(n)` 50 ms apart (or as far apart as its pauses say); then the connection is closed, or held
    open until `stop` when `hold_open`.
    """

    def __init__(
        self,
        master: Master,
        script: Script,
        node: str = "/fake_aggregator",
        topic: str = TOPIC,
        hold_open: bool = False,
        reply_header: dict[str, str] | None = None,
    ) -> None:
        """Listen on loopback and register with `master` as a publisher of `topic`."""
        self.master = master
        self.node = node
        self.topic = topic
        self.connections = 0
        self.subscriber_headers: list[dict[str, str]] = []
        self._script = script
        self._hold_open = hold_open
        self._reply_header = reply_header or {
            "callerid": node,
            "topic": topic,
            "type": MESSAGE_TYPE,
            "md5sum": MD5SUM,
            "latching": "0",
        }
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._open: list[socket.socket] = []
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(0.2)
        self._slave = SimpleXMLRPCServer(("127.0.0.1", 0), logRequests=False)
        self._slave.register_function(self._request_topic, "requestTopic")
        self._slave.register_function(lambda caller_id: [1, "", 0], "getPid")
        self._slave.register_function(lambda caller_id, topic, uris: [1, "", 0], "publisherUpdate")
        self._threads = [
            threading.Thread(target=self._slave.serve_forever, args=(0.1,), daemon=True),
            threading.Thread(target=self._accept_loop, daemon=True),
        ]
        for thread in self._threads:
            thread.start()
        self.uri = f"http://127.0.0.1:{self._slave.server_address[1]}/"
        ros_call(master.uri, "registerPublisher", node, topic, MESSAGE_TYPE, self.uri, timeout=5)

    def stop(self) -> None:
        """Unregister, close every connection and stop serving."""
        self._stop.set()
        with contextlib.suppress(RosApiError):
            ros_call(self.master.uri, "unregisterPublisher", self.node, self.topic, self.uri, timeout=5)
        with self._lock:
            for sock in self._open:
                with contextlib.suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
        self._slave.shutdown()
        self._slave.server_close()
        for thread in self._threads:
            thread.join(5)
        self._listener.close()

    def _request_topic(self, *caller_id_topic_protocols: Any) -> list[Any]:
        return [1, "", ["TCPROS", "127.0.0.1", self._listener.getsockname()[1]]]

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                sock, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            thread = threading.Thread(target=self._serve, args=(sock,), daemon=True)
            self._threads.append(thread)
            thread.start()

    def _serve(self, sock: socket.socket) -> None:
        with self._lock:
            self._open.append(sock)
            self.connections += 1
            number = self.connections
        try:
            sock.settimeout(5)
            self.subscriber_headers.append(decode_header(read_block(sock, MAX_HEADER_BYTES, "header")))
            sock.sendall(encode_header(self._reply_header))
            for chunk in self._script(number):
                if self._stop.wait(chunk if isinstance(chunk, float) else 0.05):
                    return
                if isinstance(chunk, bytes):
                    sock.sendall(chunk)
            if self._hold_open:
                self._stop.wait()
        except Exception:  # the subscriber hung up first; that is what many tests expect
            return
        finally:
            sock.close()


@contextmanager
def fake_publisher(master: Master, script: Script, **options: Any) -> Iterator[FakePublisher]:
    """A `FakePublisher` until the block ends."""
    publisher = FakePublisher(master, script, **options)
    try:
        yield publisher
    finally:
        publisher.stop()
