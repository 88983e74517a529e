"""Our node's XML-RPC slave API on one ROS 1 master: what the master and tools such as rosnode call.

The master calls `publisherUpdate` when the topic's publishers change. Since that call does not say
which master makes it, each robot gets a slave API of its own. We publish nothing and take no
orders: `requestTopic` is refused and `shutdown` is only reported (it means another node took our
caller id, and the registration loop will take it back).
"""

from __future__ import annotations

import ipaddress
import os
import socket
import threading
from collections.abc import Callable
from typing import Any
from urllib.parse import urlsplit
from xmlrpc.server import SimpleXMLRPCRequestHandler, SimpleXMLRPCServer

from overseer.sources.ros1.xmlrpc import RosApiError, uri_list

REQUEST_TIMEOUT_SECONDS = 5.0

# A slave API answer: [code, status message, value]; 1 is success, -1 the caller's error.
Answer = list[Any]


class _RequestHandler(SimpleXMLRPCRequestHandler):
    timeout = REQUEST_TIMEOUT_SECONDS  # a client that connects and says nothing cannot hold the server


class SlaveApi:
    """A subscriber's slave API for one topic on one master, served from a thread."""

    def __init__(
        self,
        caller_id: str,
        master_uri: str,
        topic: str,
        topic_type: str,
        advertise_host: str | None,
        on_publishers: Callable[[list[str]], None],
        bus_info: Callable[[], list[list[Any]]],
        on_shutdown: Callable[[str], None],
    ) -> None:
        """Bind an ephemeral port; nothing is served until `start`.

        Like rospy, it listens on every interface unless `advertise_host` is a loopback address.
        """
        self._caller_id = caller_id
        self._advertise_host = advertise_host
        self._master_uri = master_uri
        self._topic = topic
        self._topic_type = topic_type
        self._on_publishers = on_publishers
        self._bus_info = bus_info
        self._on_shutdown = on_shutdown
        bind_host = advertise_host if advertise_host and _is_loopback(advertise_host) else ""
        self._server = SimpleXMLRPCServer(
            (bind_host, 0), requestHandler=_RequestHandler, logRequests=False, allow_none=False
        )
        functions: dict[str, Callable[..., Answer]] = {
            "getBusInfo": self._get_bus_info,
            "getBusStats": self._get_bus_stats,
            "getMasterUri": self._get_master_uri,
            "shutdown": self._shutdown,
            "getPid": self._get_pid,
            "getSubscriptions": self._get_subscriptions,
            "getPublications": self._get_publications,
            "paramUpdate": self._param_update,
            "publisherUpdate": self._publisher_update,
            "requestTopic": self._request_topic,
        }
        for name, function in functions.items():
            self._server.register_function(function, name)
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        """The port the API listens on."""
        port: int = self._server.server_address[1]
        return port

    def uri(self) -> str:
        """The URI to register: at `advertise_host`, or at our address on the route to the master."""
        host = self._advertise_host or local_address_towards(self._master_uri)
        return f"http://{f'[{host}]' if ':' in host else host}:{self.port}/"

    def start(self) -> None:
        """Serve in a daemon thread."""
        self._thread = threading.Thread(target=self._server.serve_forever, name="ros1-slave-api", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop serving and close the port."""
        if self._thread is not None:
            self._server.shutdown()
            self._thread.join(timeout=REQUEST_TIMEOUT_SECONDS)
        self._server.server_close()

    def _get_bus_info(self, caller_id: str) -> Answer:
        return [1, "bus info", self._bus_info()]

    def _get_bus_stats(self, caller_id: str) -> Answer:
        return [1, "bus stats", [[], [], []]]

    def _get_master_uri(self, caller_id: str) -> Answer:
        return [1, "", self._master_uri]

    def _shutdown(self, caller_id: str, message: str = "") -> Answer:
        self._on_shutdown(f"{caller_id}: {message}")
        return [1, "shutdown ignored: a monitor keeps watching", 0]

    def _get_pid(self, caller_id: str) -> Answer:
        return [1, "", os.getpid()]

    def _get_subscriptions(self, caller_id: str) -> Answer:
        return [1, "subscriptions", [[self._topic, self._topic_type]]]

    def _get_publications(self, caller_id: str) -> Answer:
        return [1, "publications", []]

    def _param_update(self, caller_id: str, key: str, value: Any) -> Answer:
        return [1, "", 0]

    def _publisher_update(self, caller_id: str, topic: str, publishers: Any) -> Answer:
        if topic != self._topic:
            return [-1, f"not a subscriber of {topic}", 0]
        try:
            uris = uri_list(publishers, caller_id, "publisherUpdate")
        except RosApiError as error:
            return [-1, str(error), 0]
        self._on_publishers(uris)
        return [1, "", 0]

    def _request_topic(self, caller_id: str, topic: str, protocols: Any) -> Answer:
        return [-1, f"{self._caller_id} publishes nothing, so not {topic}", 0]


def local_address_towards(uri: str) -> str:
    """Our IP address on the route to the host of `uri` (OSError when it cannot be resolved)."""
    parts = urlsplit(uri)
    family, _, _, _, address = socket.getaddrinfo(parts.hostname, parts.port or 80, type=socket.SOCK_DGRAM)[0]
    with socket.socket(family, socket.SOCK_DGRAM) as probe:
        probe.connect(address)  # a UDP connect sends nothing; it only picks the route
        host: str = probe.getsockname()[0]
        return host


def _is_loopback(host: str) -> bool:
    try:
        return host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
