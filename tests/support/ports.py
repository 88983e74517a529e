"""Free loopback ports and DDS domain ids for tests that run side by side."""

from __future__ import annotations

import os
import socket
import threading

_lock = threading.Lock()
_next_domain = 0


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def fresh_domain_id() -> int:
    """A DDS domain id no other test in this run uses; runs in parallel are spread by process id.

    Domain ids map to UDP ports (7400 + 250 x id), so distinct ids keep concurrent tests apart.
    """
    global _next_domain
    with _lock:
        _next_domain += 1
        offset = _next_domain
    return 1 + (os.getpid() * 7 + offset) % 230
