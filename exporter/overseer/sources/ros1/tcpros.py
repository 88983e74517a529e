"""TCPROS for a subscriber: the connection header handshake, then length-prefixed frames, all bounded.

Both the header and every frame are a 4-byte little-endian length and that many bytes. A length
above the cap is refused before anything is read, and the bytes under the cap are gathered as they
arrive, so a lying length prefix costs no more memory than the bytes really sent.
"""

from __future__ import annotations

import socket
import struct
from collections.abc import Mapping

from overseer.codec.ros1 import MD5SUM, MESSAGE_TYPE

MAX_FRAME_BYTES = 16 * 1024 * 1024
MAX_HEADER_BYTES = 1024 * 1024
ANY_MD5SUM = "*"
_CHUNK_BYTES = 64 * 1024
_U32 = struct.Struct("<I")


class TcprosError(Exception):
    """A TCPROS connection that failed; `reason` is a short label to count it by."""

    def __init__(self, reason: str, message: str) -> None:
        """Keep the counting label and the one-line message."""
        super().__init__(message)
        self.reason = reason


def encode_header(fields: Mapping[str, str]) -> bytes:
    """A connection header: each `key=value` with its own length, the whole with a length prefix."""
    body = bytearray()
    for key, value in fields.items():
        field = f"{key}={value}".encode()
        body += _U32.pack(len(field)) + field
    return _U32.pack(len(body)) + bytes(body)


def decode_header(block: bytes) -> dict[str, str]:
    """The fields of a connection header's body (without its own length prefix)."""
    fields: dict[str, str] = {}
    pos, end = 0, len(block)
    while pos < end:
        if pos + 4 > end:
            raise TcprosError("handshake_error", "connection header ends inside a field length")
        (length,) = _U32.unpack_from(block, pos)
        pos += 4
        if length > end - pos:
            raise TcprosError("handshake_error", f"connection header field length {length} runs past its end")
        key, sep, value = block[pos : pos + length].decode("utf-8", "replace").partition("=")
        if not sep:
            raise TcprosError("handshake_error", f"connection header field {key[:50]!r} has no '='")
        fields[key] = value
        pos += length
    return fields


def subscriber_header(caller_id: str, topic: str) -> dict[str, str]:
    """The fields a subscriber of DiagnosticArray on `topic` sends."""
    return {
        "callerid": caller_id,
        "topic": topic,
        "md5sum": MD5SUM,
        "type": MESSAGE_TYPE,
        "tcp_nodelay": "1",
    }


def subscribe(host: str, port: int, caller_id: str, topic: str, timeout: float) -> socket.socket:
    """Connect to a publisher, exchange headers and return the socket, ready for `read_frame`."""
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except OSError as error:
        raise TcprosError(
            "publisher_unreachable", f"cannot connect to {host}:{port}: {describe(error)}"
        ) from None
    except UnicodeError:  # from IDNA-encoding a host name that no DNS could hold
        raise TcprosError(
            "publisher_unreachable", f"cannot connect to {host[:100]!r}: invalid host name"
        ) from None
    try:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.sendall(encode_header(subscriber_header(caller_id, topic)))
        reply = decode_header(read_block(sock, MAX_HEADER_BYTES, "connection header"))
        check_publisher_header(reply)
    except OSError as error:
        sock.close()
        raise TcprosError(
            "connection_lost", f"handshake with {host}:{port} failed: {describe(error)}"
        ) from None
    except TcprosError:
        sock.close()
        raise
    return sock


def check_publisher_header(fields: Mapping[str, str]) -> None:
    """TcprosError unless the publisher's reply accepts us and carries DiagnosticArray."""
    if "error" in fields:
        raise TcprosError("handshake_error", f"publisher refused the connection: {fields['error'][:200]}")
    md5sum = fields.get("md5sum")
    if md5sum not in (MD5SUM, ANY_MD5SUM):
        raise TcprosError(
            "handshake_error", f"publisher sends md5sum {str(md5sum)[:40]!r}, not DiagnosticArray's {MD5SUM}"
        )


def read_frame(sock: socket.socket) -> bytes:
    """The next message frame's body; TcprosError when the connection ends, stalls or lies."""
    return read_block(sock, MAX_FRAME_BYTES, "frame")


def read_block(sock: socket.socket, limit: int, what: str) -> bytes:
    """A 4-byte little-endian length then that many bytes, refusing a length above `limit`."""
    (length,) = _U32.unpack(_read_exactly(sock, 4, what))
    if length > limit:
        raise TcprosError("frame_too_large", f"{what} length {length} is above the {limit}-byte limit")
    return _read_exactly(sock, length, what)


def _read_exactly(sock: socket.socket, count: int, what: str) -> bytes:
    chunks = []
    remaining = count
    while remaining:
        try:
            chunk = sock.recv(min(remaining, _CHUNK_BYTES))
        except TimeoutError:
            raise TcprosError("idle_timeout", f"nothing received for {sock.gettimeout() or 0:g} s") from None
        except OSError as error:
            raise TcprosError(
                "connection_lost", f"connection lost reading a {what}: {describe(error)}"
            ) from None
        if not chunk:
            raise TcprosError("connection_lost", f"connection closed by the publisher (reading a {what})")
        chunks.append(chunk)
        remaining -= len(chunk)
    return b"".join(chunks)


def describe(error: OSError) -> str:
    """A short lower-case reason for a socket error, e.g. 'connection refused'."""
    if isinstance(error, TimeoutError):
        return "timed out"
    return (error.strerror or str(error) or type(error).__name__).lower()
