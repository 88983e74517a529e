"""The load generator's robots: each one's DiagnosticArray encoded once, then changed in place.

A robot's array follows the simulator's design (`overseer.simulator.design`: leaves in five groups,
and the group statuses an aggregator adds; 50 components are 45 leaves and 5 groups), encoded once
with the project's CDR encoder. Every value that changes is a fixed-width text (a voltage of 12.70
stays five characters), so a change rewrites a few bytes at an offset known from the start and
nothing moves. A robot none of whose statuses changed publishes the bytes it published before but
for its stamp, as a real aggregator republishes, which is what the exporter's skip-unchanged path
is built for.

Two profiles: `realistic`, in which a share of all statuses (1 % by default) changes each second,
drawn at random, and `live`, in which every status's value changes at every publication (the
exporter's worst case). A share of robots (2 % by default) is in trouble: one leaf in ERROR and one
in WARN. A share of robots a minute may go down and come back after a while. Pure state: the clock
is given, nothing here touches a network, so the tests drive it through simulated seconds.
"""

from __future__ import annotations

import random
import struct
from collections import deque
from dataclasses import dataclass

from overseer.codec.cdr import WIRE_FORMAT, encode_diagnostic_array
from overseer.codec.wire import decode_laid_out
from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.simulator.design import GROUPS, aggregated_statuses, initial_levels, leaf_components

REALISTIC = "realistic"
LIVE = "live"
PROFILES = (REALISTIC, LIVE)
VARIANTS = 8  # the texts each changing value takes in turn
STAMP = slice(4, 12)  # the header's stamp (seconds, nanoseconds), after the encapsulation header
LIVE_KEY = "reading"  # the value the live profile gives group statuses, which have none of their own
_U32 = struct.Struct("<I")


@dataclass(frozen=True)
class Slot:
    """A status's value that changes in place: where its text lies and the texts it takes."""

    status: int  # index of the status in the array
    offset: int  # where the value's text starts in the payload
    variants: tuple[bytes, ...]  # VARIANTS texts of one width, the design's first


@dataclass(frozen=True)
class ArrayTemplate:
    """A robot's array encoded once, and the values in it that change."""

    payload: bytes  # CDR with its encapsulation header, padded to whole words, stamp zero
    statuses: tuple[DiagnosticStatus, ...]
    slots: tuple[Slot, ...]

    def version(self, turn: int) -> bytearray:
        """The payload with every slot at its variant `turn` (modulo VARIANTS)."""
        payload = bytearray(self.payload)
        for slot in self.slots:
            text = slot.variants[turn % VARIANTS]
            payload[slot.offset : slot.offset + len(text)] = text
        return payload


def leaf_count(components: int) -> int:
    """The leaves of a robot with `components` statuses in all: its leaves and one status per group."""
    for leaves in range(1, components):
        if leaves + min(leaves, len(GROUPS)) == components:
            return leaves
    raise ValueError(
        f"{components} components: expected 10 or more, or an even number from 2 (leaves and their groups)"
    )


def value_variants(text: str) -> tuple[bytes, ...]:
    """VARIANTS texts as wide as `text`, with its decimals: it and its next steps up (or down)."""
    decimals = len(text) - text.index(".") - 1 if "." in text else 0
    value, step = float(text), 10.0**-decimals
    for direction in (1, -1):
        texts = [f"{value + direction * turn * step:.{decimals}f}" for turn in range(VARIANTS)]
        if all(len(t) == len(text) and not t.startswith("-") for t in texts):
            return tuple(t.encode() for t in texts)
    raise ValueError(f"value {text!r}: no {VARIANTS} texts of its width")


def build_template(
    components: int, levels: dict[str, Level] | None = None, live: bool = False
) -> ArrayTemplate:
    """A robot's array of `components` statuses at `levels` (all OK by default), with its slots.

    Each leaf's first value changes; with `live`, every group status carries a value that changes too.
    """
    leaves = leaf_components(leaf_count(components))
    statuses = aggregated_statuses(leaves, levels or initial_levels(leaves, 0, 0), set())
    if live:
        statuses = [s if s.values else s._replace(values=((LIVE_KEY, "50.0"),)) for s in statuses]
    encoded = encode_diagnostic_array(DiagnosticArray(0, 0, "", tuple(statuses)))
    payload = encoded + b"\x00" * (-len(encoded) & 3)
    bounds = decode_laid_out(WIRE_FORMAT, payload).bounds
    slots = []
    for index, status in enumerate(statuses):
        if status.values:
            key, text = status.values[0]
            offset = value_offset(payload, bounds[index], bounds[index + 1], key, text)
            slots.append(Slot(index, offset, value_variants(text)))
    return ArrayTemplate(payload, tuple(statuses), tuple(slots))


def value_offset(payload: bytes, start: int, end: int, key: str, text: str) -> int:
    """Where the text of the value of `key` starts in the status encoded in payload[start:end]."""
    needle = _U32.pack(len(key) + 1) + key.encode() + b"\x00"
    at = payload.find(needle, start, end)
    pos = (at + len(needle) + 3) & ~3
    if at < 0 or payload[pos : pos + 4] != _U32.pack(len(text) + 1):
        raise ValueError(f"value {key!r} not found where the encoder put it")
    return pos + 4


@dataclass(frozen=True)
class FleetShape:
    """Which fleet, and how it changes."""

    robots: int
    components: int = 50
    profile: str = REALISTIC
    change_share: float = 0.01  # of all statuses, per second (realistic profile)
    trouble_share: float = 0.02  # of robots, with one leaf in ERROR and one in WARN
    down_share: float = 0.0  # of robots going down, per minute
    down_seconds: float = 30.0  # how long a robot that went down stays down
    seed: int = 1


class Fleet:
    """Every robot's payload, the changes made to them, and which robots are down; driven by a given clock."""

    def __init__(self, shape: FleetShape) -> None:
        """Encode the fleet's arrays; the change profile starts counting at the first `advance`."""
        self.shape = shape
        self._random = random.Random(shape.seed)
        live = shape.profile == LIVE
        healthy = build_template(shape.components, live=live)
        leaves = leaf_components(leaf_count(shape.components))
        troubled = build_template(shape.components, initial_levels(leaves, 1, 1), live)
        trouble_count = round(shape.trouble_share * shape.robots)
        self.trouble = frozenset(self._random.sample(range(shape.robots), trouble_count))
        self.templates = [troubled if i in self.trouble else healthy for i in range(shape.robots)]
        if live:
            # Every status differs between consecutive publications: a robot's turn picks the version.
            versions = {id(t): [t.version(turn) for turn in range(VARIANTS)] for t in (healthy, troubled)}
            self._versions = [versions[id(t)] for t in self.templates]
            self._turns = bytearray(shape.robots)
            self.payloads = [v[0] for v in self._versions]
        else:
            self.payloads = [bytearray(t.payload) for t in self.templates]
            self._variant = [bytearray(len(t.slots)) for t in self.templates]
        self.changed = 0  # statuses changed so far
        self._statuses = shape.components * shape.robots
        self._changes_owed = 0.0
        self._downs_owed = 0.0
        self._last: float | None = None
        self.down: set[int] = set()
        self._returns: deque[tuple[float, int]] = deque()

    def advance(self, now: float) -> tuple[list[int], list[int]]:
        """Make the changes due by `now` (realistic profile); the robots that go down and come back."""
        elapsed, self._last = (0.0 if self._last is None else now - self._last), now
        if self.shape.profile == REALISTIC:
            self._changes_owed += self.shape.change_share * self._statuses * elapsed
            count = int(self._changes_owed)
            self._changes_owed -= count
            self._change(count)
        went_down, came_back = [], []
        while self._returns and self._returns[0][0] <= now:
            robot = self._returns.popleft()[1]
            self.down.discard(robot)
            came_back.append(robot)
        self._downs_owed += self.shape.down_share * self.shape.robots * elapsed / 60.0
        while self._downs_owed >= 1.0 and len(self.down) < self.shape.robots:
            self._downs_owed -= 1.0
            robot = self._random.randrange(self.shape.robots)
            while robot in self.down:
                robot = self._random.randrange(self.shape.robots)
            self.down.add(robot)
            self._returns.append((now + self.shape.down_seconds, robot))
            went_down.append(robot)
        return went_down, came_back

    def turn(self, first: int, stop: int) -> None:
        """Live profile: the robots up from `first` to `stop` - 1 take their next version (all values new)."""
        versions, turns, payloads, down = self._versions, self._turns, self.payloads, self.down
        turned = 0
        for robot in range(first, stop):
            if robot not in down:
                turns[robot] = (turns[robot] + 1) % VARIANTS
                payloads[robot] = versions[robot][turns[robot]]
                turned += 1
        self.changed += turned * len(self.templates[first].slots)

    def _change(self, count: int) -> None:
        """Move `count` values, drawn at random among every robot's slots, to their next variant."""
        draw, robots, payloads, variants = (
            self._random.random,
            self.shape.robots,
            self.payloads,
            self._variant,
        )
        for _ in range(count):
            robot = int(draw() * robots)
            slots = self.templates[robot].slots
            index = int(draw() * len(slots))
            slot, variant = slots[index], variants[robot]
            variant[index] = (variant[index] + 1) % VARIANTS
            text = slot.variants[variant[index]]
            payloads[robot][slot.offset : slot.offset + len(text)] = text
        self.changed += count
