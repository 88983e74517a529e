"""A network namespace joined to the host by a veth pair, for cutting one robot's link (needs root).

Addresses are private /30s in 10.213.0.0/16, configured only on the pair, so nothing leaves the
machine. The namespace, and with it both ends of the pair, is deleted when the block ends.

Commands run inside it through `nsenter --net`, which joins its network and nothing else: `ip -n` and
`ip netns exec` also remount / as a slave, which fails where / is not a mount point (a chroot).
"""

from __future__ import annotations

import itertools
import os
import subprocess
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

_counter = itertools.count(1)
NETNS_DIR = "/run/netns"  # where `ip netns add` names the namespaces


def in_namespace(name: str, args: Sequence[str]) -> list[str]:
    """`args` as a command that runs in network namespace `name`."""
    return ["nsenter", f"--net={NETNS_DIR}/{name}", *args]


def ip(*args: str, inside: str | None = None) -> None:
    """Run `ip` with `args` (in namespace `inside` if given), failing with its message."""
    command = ["ip", *args] if inside is None else in_namespace(inside, ["ip", *args])
    result = subprocess.run(command, capture_output=True, text=True, timeout=30)
    if result.returncode != 0:
        raise RuntimeError(f"{' '.join(command)}: {result.stderr.strip()}")


@dataclass(frozen=True)
class VethNamespace:
    """A namespace `name` whose interface `inside` (`inside_address`) pairs with `outside` on the host."""

    name: str
    outside: str
    inside: str
    outside_address: str
    inside_address: str

    def command(self, args: Sequence[str]) -> list[str]:
        """`args` as a command that runs inside the namespace."""
        return in_namespace(self.name, args)

    def cut(self) -> None:
        """Take the link down: nothing passes either way."""
        ip("link", "set", self.outside, "down")

    def restore(self) -> None:
        """Bring the link back up (its addresses and routes come back with it)."""
        ip("link", "set", self.outside, "up")


@contextmanager
def veth_namespace(multicast: bool = True) -> Iterator[VethNamespace]:
    """A fresh namespace with a veth pair to the host, both ends up and addressed; always removed.

    With `multicast` false, both ends of the pair and the namespace's loopback lose the MULTICAST flag,
    as on a network that carries no multicast: DDS can then discover only by unicast.
    """
    number = next(_counter)
    tag = f"{os.getpid() % 100_000}{number}"
    subnet = (os.getpid() * 7 + number) % 250 + 1
    namespace = VethNamespace(
        f"overseer-test-{tag}", f"ovs{tag}h", f"ovs{tag}n", f"10.213.{subnet}.1", f"10.213.{subnet}.2"
    )
    ip("netns", "add", namespace.name)
    try:
        ip("link", "add", namespace.outside, "type", "veth", "peer", "name", namespace.inside)
        ip("link", "set", namespace.inside, "netns", namespace.name)
        ip("addr", "add", f"{namespace.outside_address}/30", "dev", namespace.outside)
        ip("link", "set", namespace.outside, "up")
        inside = namespace.name
        ip("addr", "add", f"{namespace.inside_address}/30", "dev", namespace.inside, inside=inside)
        ip("link", "set", namespace.inside, "up", inside=inside)
        ip("link", "set", "lo", "up", inside=inside)
        if not multicast:
            ip("link", "set", namespace.outside, "multicast", "off")
            ip("link", "set", namespace.inside, "multicast", "off", inside=inside)
            ip("link", "set", "lo", "multicast", "off", inside=inside)
        yield namespace
    finally:
        subprocess.run(["ip", "link", "del", namespace.outside], capture_output=True, timeout=30)
        ip("netns", "del", namespace.name)
