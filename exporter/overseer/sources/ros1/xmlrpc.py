"""ROS 1's XML-RPC calls as a subscriber makes them: to a master, and to a publisher's slave API.

Calls go over `http.client` with `xmlrpc.client` only for the XML, so every call has a timeout and
an answer is read up to a bound. Every ROS API answers `[code, status message, value]`; anything
else, and any code but 1, is a `RosApiError`, as is a master or node that cannot be reached.
"""

from __future__ import annotations

import http.client
import xmlrpc.client
from typing import Any
from urllib.parse import urlsplit
from xml.parsers.expat import ExpatError

from overseer.sources.ros1.tcpros import describe

MAX_ANSWER_BYTES = 4 * 1024 * 1024
CALL_TIMEOUT_SECONDS = 5.0
_SUCCESS = 1


class RosApiError(Exception):
    """A ROS XML-RPC call that failed; `unreachable` when no answer came at all."""

    def __init__(self, message: str, *, unreachable: bool) -> None:
        """Keep the one-line `message` and whether the peer was unreachable."""
        super().__init__(message)
        self.unreachable = unreachable


def ros_call(uri: str, method: str, *params: Any, timeout: float) -> Any:
    """Call `method` on the ROS XML-RPC API at `uri` and return the value of a successful answer."""
    parts = urlsplit(uri)
    connection_class = http.client.HTTPSConnection if parts.scheme == "https" else http.client.HTTPConnection
    body = xmlrpc.client.dumps(params, method).encode("utf-8")
    try:
        connection = connection_class(parts.hostname or "", parts.port, timeout=timeout)
    except (ValueError, http.client.HTTPException) as error:  # a port out of range, say
        raise RosApiError(f"invalid URI {uri!r}: {error}", unreachable=True) from None
    try:
        connection.request("POST", parts.path or "/", body, {"Content-Type": "text/xml"})
        response = connection.getresponse()
        data = response.read(MAX_ANSWER_BYTES + 1)
    except OSError as error:
        raise RosApiError(f"{uri} unreachable: {describe(error)}", unreachable=True) from None
    except UnicodeError:  # from IDNA-encoding a host name that no DNS could hold
        raise RosApiError(f"{uri} unreachable: invalid host name", unreachable=True) from None
    except http.client.HTTPException as error:
        raise RosApiError(f"{uri} broke off its answer to {method}: {error!r}", unreachable=False) from None
    finally:
        connection.close()
    if response.status != 200:
        raise RosApiError(f"{uri} answered {method} with HTTP {response.status}", unreachable=False)
    if len(data) > MAX_ANSWER_BYTES:
        raise RosApiError(
            f"{uri} answered {method} with more than {MAX_ANSWER_BYTES} bytes", unreachable=False
        )
    try:
        (answer,), _ = xmlrpc.client.loads(data)
    except (xmlrpc.client.Error, ExpatError, ValueError, TypeError) as error:
        raise RosApiError(
            f"{uri} answered {method} with malformed XML-RPC: {error}", unreachable=False
        ) from None
    if not isinstance(answer, list) or len(answer) != 3 or not isinstance(answer[0], int):
        raise RosApiError(f"{uri} answered {method} with {str(answer)[:100]!r}", unreachable=False)
    code, status, value = answer
    if code != _SUCCESS:
        raise RosApiError(f"{uri} refused {method}: {str(status)[:200]}", unreachable=False)
    return value


def register_subscriber(
    master_uri: str, caller_id: str, topic: str, topic_type: str, caller_api: str, timeout: float
) -> list[str]:
    """Subscribe `caller_api` to `topic` at the master; returns the publishers' slave API URIs."""
    value = ros_call(
        master_uri, "registerSubscriber", caller_id, topic, topic_type, caller_api, timeout=timeout
    )
    return uri_list(value, master_uri, "registerSubscriber")


def unregister_subscriber(
    master_uri: str, caller_id: str, topic: str, caller_api: str, timeout: float
) -> None:
    """Withdraw the subscription that `register_subscriber` made."""
    ros_call(master_uri, "unregisterSubscriber", caller_id, topic, caller_api, timeout=timeout)


def topic_publishers(master_uri: str, caller_id: str, topic: str, timeout: float) -> list[str]:
    """The slave API URIs of `topic`'s publishers, asked without registering (getSystemState, lookupNode)."""
    state = ros_call(master_uri, "getSystemState", caller_id, timeout=timeout)
    try:
        publications = {entry[0]: entry[1] for entry in state[0]}
    except (TypeError, IndexError, KeyError) as error:
        raise RosApiError(f"{master_uri} answered getSystemState with {error!r}", unreachable=False) from None
    nodes = publications.get(topic, [])
    if not isinstance(nodes, list):
        raise RosApiError(f"{master_uri} listed {topic}'s publishers as {nodes!r}", unreachable=False)
    uris = []
    for node in nodes:
        try:
            uris.append(ros_call(master_uri, "lookupNode", caller_id, node, timeout=timeout))
        except RosApiError as error:
            if error.unreachable:
                raise
            continue  # the node unregistered since getSystemState
    return uri_list(uris, master_uri, "lookupNode")


def request_topic(publisher_uri: str, caller_id: str, topic: str, timeout: float) -> tuple[str, int]:
    """Ask a publisher's slave API where to connect over TCPROS for `topic`: (host, port)."""
    value = ros_call(publisher_uri, "requestTopic", caller_id, topic, [["TCPROS"]], timeout=timeout)
    if (
        not isinstance(value, list)
        or len(value) != 3
        or value[0] != "TCPROS"
        or not isinstance(value[1], str)
        or not isinstance(value[2], int)
        or not 0 < value[2] < 65536
    ):
        raise RosApiError(f"{publisher_uri} offered {str(value)[:100]!r}, not TCPROS", unreachable=False)
    return value[1], value[2]


def uri_list(value: object, source: str, method: str) -> list[str]:
    """`value` as a list of http URIs; RosApiError naming `source` and `method` otherwise."""
    if not isinstance(value, list) or not all(
        isinstance(uri, str) and uri.startswith(("http://", "https://")) for uri in value
    ):
        raise RosApiError(f"{source} answered {method} with {str(value)[:100]!r}", unreachable=False)
    return value
