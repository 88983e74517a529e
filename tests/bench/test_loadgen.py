"""The load generator's payloads, change profile, pacing and wire, without a network.

Every payload is checked with the project's own decoder: what the generator claims to publish is what
an exporter would read.
"""

from __future__ import annotations

import argparse
import json
import threading
import time
from collections.abc import Sequence

import pytest
import zenoh

from bench.loadgen import (
    LoadGenerator,
    LoadSettings,
    Pacing,
    add_arguments,
    main,
    settings_of,
    shape_arguments,
)
from bench.loadgen_payloads import (
    LIVE,
    STAMP,
    VARIANTS,
    Fleet,
    FleetShape,
    leaf_count,
    value_variants,
)
from bench.loadgen_wire import SESSION_TX_BATCHES, ZenohEndpoints, ZenohWire, patch_attachment, session_config
from overseer.codec.cdr import decode_diagnostic_array
from overseer.levels import Level
from overseer.messages import DiagnosticArray
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.zenoh.keys import (
    ATTACHMENT_SIZE,
    DIAGNOSTIC_ARRAY_HASH,
    attachment_gid,
    data_key,
    parse_data_key,
    parse_publisher,
)


def decoded(payload: bytes | bytearray) -> DiagnosticArray:
    """The array an exporter reads from `payload`."""
    return decode_diagnostic_array(bytes(payload))


def changed_bytes(before: bytes, after: bytes) -> set[int]:
    """The offsets at which two payloads of one length differ."""
    assert len(before) == len(after)
    return {i for i, (a, b) in enumerate(zip(before, after, strict=True)) if a != b}


def stamped(payload: bytearray, second: int) -> bytes:
    """The payload as a wire sends it at `second`: stamp patched in place."""
    payload[STAMP] = second.to_bytes(4, "little") + (123).to_bytes(4, "little")
    return bytes(payload)


def test_fifty_components_are_45_leaves_in_five_groups() -> None:
    assert leaf_count(50) == 45 and leaf_count(10) == 5 and leaf_count(4) == 2
    with pytest.raises(ValueError, match="7 components"):
        leaf_count(7)


def test_each_pre_encoded_payload_decodes_to_exactly_the_statuses_it_claims() -> None:
    fleet = Fleet(FleetShape(robots=20, trouble_share=0.25))
    for robot, payload in enumerate(fleet.payloads):
        array = decoded(payload)
        template = fleet.templates[robot]
        assert array.statuses == template.statuses
        assert len(array.statuses) == 50
        assert sum(1 for s in array.statuses if s.name.count("/") == 1) == 5  # the group statuses
        for slot in template.slots:
            text = array.statuses[slot.status].values[0][1].encode()
            assert text == slot.variants[0] == payload[slot.offset : slot.offset + len(text)]


def test_values_take_texts_of_their_own_width() -> None:
    assert value_variants("12.70") == tuple(f"12.{70 + i}".encode() for i in range(VARIANTS))
    assert value_variants("0.0")[:3] == (b"0.0", b"0.1", b"0.2")
    assert value_variants("99.9") == tuple(f"{99.9 - i / 10:.1f}".encode() for i in range(VARIANTS))


def test_an_unchanged_robots_payload_differs_from_its_last_only_in_the_stamp() -> None:
    fleet = Fleet(FleetShape(robots=100, change_share=0.01))
    fleet.advance(0.0)
    before = [stamped(p, 1) for p in fleet.payloads]
    fleet.advance(1.0)  # 1 % of 5,000 statuses: 50 changes, so most robots change nothing
    after = [stamped(p, 2) for p in fleet.payloads]
    unchanged = [r for r in range(100) if decoded(before[r]).statuses == decoded(after[r]).statuses]
    assert 40 <= len(unchanged) < 100
    for robot in unchanged:
        assert changed_bytes(before[robot], after[robot]) == {4}  # the stamp's seconds, 1 → 2
    for robot in set(range(100)) - set(unchanged):
        slots = fleet.templates[robot].slots
        in_slots = {o for s in slots for o in range(s.offset, s.offset + len(s.variants[0]))}
        assert changed_bytes(before[robot], after[robot]) <= in_slots | {4}


def test_a_changed_status_decodes_to_its_new_value_and_nothing_else_changes() -> None:
    fleet = Fleet(FleetShape(robots=1, change_share=1 / 50))  # one status a second
    fleet.advance(0.0)
    before = decoded(fleet.payloads[0]).statuses
    fleet.advance(1.0)
    after = decoded(fleet.payloads[0]).statuses
    changed = [i for i in range(50) if before[i] != after[i]]
    assert len(changed) == 1 and fleet.changed == 1
    status, old = after[changed[0]], before[changed[0]]
    slot = next(s for s in fleet.templates[0].slots if s.status == changed[0])
    assert status.values[0][1].encode() == slot.variants[1]
    assert status._replace(values=old.values) == old  # level, name, message, other values as they were
    assert status.values[1:] == old.values[1:]


def test_the_change_profile_changes_the_asked_share_of_statuses_each_second() -> None:
    robots, seconds, share = 200, 10, 0.01
    fleet = Fleet(FleetShape(robots=robots, change_share=share, seed=7))
    fleet.advance(0.0)
    previous = [decoded(p).statuses for p in fleet.payloads]
    differences = 0
    for tick in range(1, seconds * 100 + 1):  # advanced every 10 ms, compared every second
        fleet.advance(tick / 100)
        if tick % 100 == 0:
            current = [decoded(p).statuses for p in fleet.payloads]
            differences += sum(
                a != b
                for old, new in zip(previous, current, strict=True)
                for a, b in zip(old, new, strict=True)
            )
            previous = current
    expected = share * 50 * robots * seconds  # 1,000
    assert abs(fleet.changed - expected) <= 1
    assert 0.97 * expected <= differences <= fleet.changed  # a value changed twice in a second counts once


def test_the_trouble_share_of_robots_has_a_leaf_in_error_and_one_in_warn() -> None:
    fleet = Fleet(FleetShape(robots=500, trouble_share=0.02, seed=3))
    troubled = []
    for robot, payload in enumerate(fleet.payloads):
        leaves = [s for s in decoded(payload).statuses if s.name.count("/") == 2]
        levels = sorted(s.level for s in leaves if s.level != Level.OK)
        if levels:
            assert levels == [Level.WARN, Level.ERROR]
            troubled.append(robot)
    assert len(troubled) == 10 and set(troubled) == fleet.trouble
    assert Fleet(FleetShape(robots=500, trouble_share=0.02, seed=3)).trouble == fleet.trouble


def test_robots_go_down_at_the_asked_share_a_minute_and_come_back_after_their_down_time() -> None:
    fleet = Fleet(FleetShape(robots=100, down_share=0.6, down_seconds=2.0))  # one robot a second
    fleet.advance(0.0)
    went, came = [], []
    for second in range(1, 11):
        down, back = fleet.advance(float(second))
        went += down
        came += back
    assert len(went) == 10 and len(set(went)) == 10
    assert came == went[:8]  # those down for 2 s by second 10
    assert fleet.down == set(went[8:])


def test_the_wire_is_told_when_the_fleet_is_declared_and_after_each_second_robots_went_or_came() -> None:
    wire = RecordingWire()
    shape = FleetShape(robots=60, components=10, down_share=1.0, down_seconds=1.0)  # one robot a second
    LoadGenerator(LoadSettings(shape, rate=2.0, duration=3.5), wire).run()
    assert wire.declarations[0] == set(range(60))  # before the first publication, once for the fleet
    changes = wire.declarations[1:]
    assert 2 <= len(changes) <= 8  # one a second that changed, not one per open or close
    assert all(len(open_robots) in (58, 59) for open_robots in changes)


def test_the_live_profile_changes_every_status_at_every_publication() -> None:
    fleet = Fleet(FleetShape(robots=3, profile=LIVE))
    before = [bytes(p) for p in fleet.payloads]
    fleet.turn(0, 3)
    after = [bytes(p) for p in fleet.payloads]
    for robot in range(3):
        old, new = decoded(before[robot]).statuses, decoded(after[robot]).statuses
        assert all(a.values != b.values for a, b in zip(old, new, strict=True))
        assert [a._replace(values=()) for a in old] == [b._replace(values=()) for b in new]
    assert fleet.changed == 3 * 50


def test_pacing_spreads_a_periods_publications_evenly_and_counts_late_and_missed() -> None:
    pacing = Pacing(robots=1000, rate=1.0)
    slices = [pacing.due(tick / 100) for tick in range(101)]  # every 10 ms for a second
    robots = [robot for ranges in slices for due in ranges for robot in due]
    assert robots == [*range(1000), 0]  # robot i due at i ms, robot 0 again at 1 s
    assert {sum(len(r) for r in ranges) for ranges in slices[1:]} == {10}
    assert pacing.late == 0 and pacing.missed == 0
    late = Pacing(robots=1000, rate=1.0)
    assert [r for r in late.due(0.5)] == [range(0, 501)]
    assert late.late == 401  # due before 0.4 s
    behind = Pacing(robots=100, rate=2.0)
    ranges = behind.due(1.2)  # 2.4 periods: the first 1.4 periods' are skipped
    assert behind.missed == 141 and sum(len(r) for r in ranges) == 100
    assert ranges == [range(41, 100), range(0, 41)]


class RecordingWire:
    """A wire that keeps what it was asked to send."""

    failed = 0

    def __init__(self) -> None:
        """Nothing sent yet."""
        self.sent: list[tuple[int, bytes]] = []
        self.open_robots: set[int] = set()
        self.declarations: list[set[int]] = []  # the robots open at each `declared`

    def open(self, robot: int) -> None:
        """The robot is up."""
        self.open_robots.add(robot)

    def close(self, robot: int) -> None:
        """The robot is down."""
        self.open_robots.discard(robot)

    def declared(self) -> None:
        """Note which robots were open."""
        self.declarations.append(set(self.open_robots))

    def publish(self, first: int, stop: int, payloads: Sequence[bytearray], stamp: bytes) -> int:
        """Keep each open robot's stamped payload."""
        for robot in range(first, stop):
            if robot in self.open_robots:
                self.sent.append((robot, stamped_with(payloads[robot], stamp)))
        return sum(1 for robot in range(first, stop) if robot in self.open_robots)

    def every_robot_subscribed(self) -> bool:
        """Always."""
        return True

    def shut(self) -> None:
        """Nothing to close."""


def stamped_with(payload: bytearray, stamp: bytes) -> bytes:
    """The payload with `stamp` patched in, as the wires do."""
    payload[STAMP] = stamp
    return bytes(payload)


def test_the_generator_publishes_every_robot_at_its_rate_with_the_time_as_stamp() -> None:
    wire = RecordingWire()
    settings = LoadSettings(FleetShape(robots=20, components=10), rate=10.0, duration=0.5)
    started = time.time()
    figures = LoadGenerator(settings, wire).run()
    assert figures.published == len(wire.sent) and 50 <= figures.published <= 102  # 100 due; a busy host
    counts = [sum(1 for robot, _ in wire.sent if robot == r) for r in range(20)]
    assert max(counts) - min(counts) <= 1
    for _, payload in wire.sent:
        array = decoded(payload)
        assert started - 1 <= array.stamp_sec + array.stamp_nanosec / 1e9 <= time.time()
    assert figures.cpu_percent_per_1000_robots == pytest.approx(figures.cpu_percent * 50, rel=0.01)


class TimingWire(RecordingWire):
    """A recording wire that also notes when robots were declared and when it first published."""

    def __init__(self) -> None:
        """Nothing declared or sent yet."""
        super().__init__()
        self.last_opened = self.first_published = 0.0

    def open(self, robot: int) -> None:
        """The robot is up, now."""
        super().open(robot)
        self.last_opened = time.monotonic()

    def publish(self, first: int, stop: int, payloads: Sequence[bytearray], stamp: bytes) -> int:
        """Keep the payloads; the moment of the first publication."""
        self.first_published = self.first_published or time.monotonic()
        return super().publish(first, stop, payloads, stamp)


def test_a_head_start_holds_the_first_publication_back_and_is_not_counted_as_publishing() -> None:
    wire = TimingWire()
    settings = LoadSettings(FleetShape(robots=20, components=10), rate=10.0, duration=0.3, head_start=0.5)
    figures = LoadGenerator(settings, wire).run()
    assert wire.first_published - wire.last_opened >= 0.45  # an event's wait may end a hair early
    assert figures.seconds < 1.0 and figures.published >= 20  # the window is the publishing, not the wait


def test_the_generator_stops_when_asked() -> None:
    generator = LoadGenerator(LoadSettings(FleetShape(robots=5, components=10)), RecordingWire())
    threading.Timer(0.2, generator.stop).start()
    assert generator.run().seconds < 5


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--components=7"], "--components: 7 components"),
        (["--change-share=2"], "--change-share: expected a share from 0 to 1, got 2.0"),
        (["--robots=0"], "--robots: must be at least 1, got 0"),
        (["--namespace-prefix=9x"], "--namespace-prefix: expected ROS name tokens, got '9x'"),
        (["--head-start=-1"], "--head-start: must be a finite number of seconds, not negative, got -1.0"),
        (["--head-start=inf"], "--head-start: must be a finite number of seconds, not negative, got inf"),
    ],
)
def test_bad_arguments_are_refused_with_the_flag_named(
    arguments: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit):
        main(arguments)
    assert message in capsys.readouterr().err


def test_a_fleets_arguments_give_the_generator_that_same_fleet() -> None:
    shape = FleetShape(
        robots=123,
        components=20,
        profile=LIVE,
        change_share=0.037,
        trouble_share=0.1,
        down_share=0.05,
        down_seconds=12.5,
        seed=7,
    )
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    settings = settings_of(parser.parse_args(shape_arguments(shape, 2.5)))
    assert (settings.shape, settings.rate) == (shape, 2.5)


def test_the_attachment_is_patched_to_rmw_zenohs_33_bytes() -> None:
    gid = bytes(range(16))
    patched = bytearray(attachment(0, 0, gid))
    patch_attachment(patched, 0, 42, 1_700_000_000_123_456_789)
    assert bytes(patched) == attachment(42, 1_700_000_000_123_456_789, gid)
    assert len(patched) == ATTACHMENT_SIZE and attachment_gid(bytes(patched)) == gid


def test_the_zenoh_wire_puts_rmw_zenoh_keys_attachments_and_stamped_payloads() -> None:
    names = ["site_a/robot1", "site_a/robot2"]
    wire = ZenohWire(names, 0, ZenohEndpoints())  # a peer that neither listens nor connects
    session = wire.sessions[0]
    received: list[zenoh.Sample] = []
    subscriber = session.declare_subscriber("0/**", received.append)
    try:
        fleet = Fleet(FleetShape(robots=2, components=10))
        for robot in range(2):
            wire.open(robot)
        tokens = [reply.ok.key_expr for reply in session.liveliness().get("@ros2_lv/**") if reply.ok]
        stamp = (1_700_000_000).to_bytes(4, "little") + (5).to_bytes(4, "little")
        assert wire.publish(0, 2, fleet.payloads, stamp) == 2
        wire.close(1)
        assert wire.publish(0, 2, fleet.payloads, stamp) == 1
        deadline = time.monotonic() + 5
        while len(received) < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        subscriber.undeclare()  # type: ignore[no-untyped-call]
        wire.shut()
    assert [str(s.key_expr) for s in received] == [
        data_key(0, n, "diagnostics_agg") for n in [*names, names[0]]
    ]
    assert parse_data_key(str(received[0].key_expr), 0).type_hash == DIAGNOSTIC_ARRAY_HASH
    publishers = {p.topic.namespace: p for p in (parse_publisher(str(t), 0) for t in tokens) if p}
    assert set(publishers) == set(names) and len(tokens) == 4  # a node and a publisher token each
    first, again = received[0], received[2]
    gid = attachment_gid(first.attachment.to_bytes() if first.attachment else None)
    assert gid == publishers["site_a/robot1"].gid
    assert decoded(first.payload.to_bytes()).stamp_sec == 1_700_000_000
    assert decoded(first.payload.to_bytes()).statuses == fleet.templates[0].statuses
    sequence = [int.from_bytes(s.attachment.to_bytes()[:8], "little") for s in (first, again) if s.attachment]
    assert sequence == [1, 2]


def test_a_generator_session_holds_more_than_zenohs_two_batches_for_a_thousand_robots_data() -> None:
    config = session_config(ZenohEndpoints(("tcp/127.0.0.1:7447",), (), "client", 1000))
    assert json.loads(config.get_json("transport/link/tx/queue/size/data")) == SESSION_TX_BATCHES
    assert SESSION_TX_BATCHES >= 16
    assert json.loads(zenoh.Config().get_json("transport/link/tx/queue/size/data")) == 2
    assert json.loads(config.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7447"]
