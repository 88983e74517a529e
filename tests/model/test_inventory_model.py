"""The inventory in the model: listed robots, expected components, remembered and retired robots.

And the event of every robot forgotten.
"""

from __future__ import annotations

import re

from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import (
    Expectation,
    FleetLimits,
    FleetModel,
    FleetSnapshot,
    Inventory,
    ListedRobot,
    RememberedRobot,
    RobotState,
)
from overseer.model.events import Event
from overseer.model.inventory import is_stand_in
from overseer.model.state import UNREPORTED
from overseer.model.transitions import TransitionDetector

START = 1_700_000_000.0
BATTERY = Expectation("/Power/Battery", exact="/Power/Battery")
WHEELS = Expectation("/Wheels/*", prefix="/Wheels/", at_least=4)
CAMERAS = Expectation("cam_[0-9]: Rate", pattern=re.compile("cam_[0-9]: Rate"), at_least=2)
TB4 = ListedRobot((("model", "tb4"), ("site", "a")), (BATTERY, WHEELS, CAMERAS))


class Fleet:
    """A model on a hand-moved clock with a detector collecting its events."""

    def __init__(self, **limits: float) -> None:
        """An empty fleet at START."""
        self.now = START
        self.limits = FleetLimits(**limits)  # type: ignore[arg-type]
        self.model = FleetModel(self.limits, clock=lambda: self.now)
        self.events: list[Event] = []
        self.detector = TransitionDetector(self.limits, self.events.extend)
        self.model.set_level_listener(self.detector.on_level_changes)

    def publish(self, robot: str, *names: str, level: int = 0) -> None:
        """One array of OK statuses called `names` from `robot`."""
        statuses = tuple(DiagnosticStatus(level, name, "fine", "hw", ()) for name in names)
        self.model.apply(robot, DiagnosticArray(0, 0, "", statuses), "dds", feed="writer")

    def check(self) -> None:
        """The detector's periodic comparison."""
        self.detector.check(self.model.told_snapshot())

    def take(self) -> list[tuple[str, str, str | None]]:
        """(kind, robot, component) of the events since the last call."""
        taken: list[tuple[str, str, str | None]] = [
            (event.kind, event.robot, event.component) for event in self.events
        ]
        self.events.clear()
        return taken

    def robot(self, name: str) -> tuple[FleetSnapshot, RobotState]:
        """The snapshot now and one robot of it."""
        snapshot = self.model.snapshot()
        robot = snapshot.find(name)
        assert robot is not None, name
        return snapshot, robot

    def components(self, name: str) -> dict[str, tuple[Level, str]]:
        """Component name → (level now, message) of one robot."""
        snapshot, robot = self.robot(name)
        up = snapshot.robot_up(robot)
        return {
            key[0]: (snapshot.component_level(robot, key, component, up), component.message)
            for key, component in robot.components.items()
        }


def test_a_listed_robot_never_heard_is_down_with_its_expected_components_stale() -> None:
    fleet = Fleet()
    fleet.model.set_inventory(Inventory({"r1": TB4}))
    snapshot, robot = fleet.robot("r1")
    assert (snapshot.robot_up(robot), robot.last_message, robot.listing) == (False, None, TB4)
    assert fleet.components("r1") == {
        "/Power/Battery": (Level.STALE, UNREPORTED),
        "/Wheels/*": (
            Level.STALE,
            "expected at least 4 components matching /Wheels/*: none reported, 4 missing",
        ),
        "cam_[0-9]: Rate": (
            Level.STALE,
            "expected at least 2 components matching cam_[0-9]: Rate: none reported, 2 missing",
        ),
    }
    fleet.now += 30 * 86400  # never forgotten, however long it stays silent
    fleet.model.expire()
    fleet.check()
    assert fleet.robot("r1")[1].listing == TB4
    assert fleet.take() == []  # a robot never heard has no event: it is down from the start


def test_an_expected_component_reported_takes_its_stand_ins_place_and_appears() -> None:
    fleet = Fleet()
    fleet.model.set_inventory(Inventory({"r1": TB4}))
    fleet.check()
    fleet.publish("r1", "/Power/Battery", "/Wheels/FL", "cam_1: Rate", "cam_2: Rate", "/Other")
    fleet.check()
    assert fleet.components("r1") == {
        "/Power/Battery": (Level.OK, "fine"),
        "/Wheels/FL": (Level.OK, "fine"),
        "cam_1: Rate": (Level.OK, "fine"),
        "cam_2: Rate": (Level.OK, "fine"),
        "/Other": (Level.OK, "fine"),
        "/Wheels/*": (
            Level.STALE,
            "expected at least 4 components matching /Wheels/*: 1 reported, 3 missing",
        ),
    }
    events = fleet.take()
    assert ("appeared", "r1", "/Power/Battery") in events
    assert not [event for event in events if event[0] == "level"]  # a stand-in replaced is no level change
    fleet.publish("r1", "/Power/Battery", "/Wheels/FL", "/Wheels/FR", "/Wheels/RL", "/Wheels/RR")
    assert "/Wheels/*" not in fleet.components("r1")


def test_a_stand_in_goes_stale_without_an_event_and_an_expected_component_that_stops_never_expires() -> None:
    fleet = Fleet(stale_after=5, robot_timeout=10, expire_after=60)
    fleet.model.set_inventory(Inventory({"r1": ListedRobot((), (BATTERY, WHEELS))}))
    fleet.publish("r1", "/Power/Battery", "/Noise")
    fleet.check()
    fleet.take()
    for _ in range(70):
        fleet.now += 1
        fleet.publish("r1", "/Keepalive")  # another node of the robot speaks on
        fleet.model.expire()
        fleet.check()
    events = fleet.take()
    missing = [event for event in events if event[0] == "missing"]
    assert sorted(missing) == [("missing", "r1", "/Noise"), ("missing", "r1", "/Power/Battery")]
    assert ("expired", "r1", "/Noise") in events  # not expected: forgotten after expire_after
    fleet.model.expire()
    assert fleet.components("r1")["/Power/Battery"] == (Level.STALE, "fine")  # expected: kept, STALE
    assert "/Wheels/*" in fleet.components("r1")


def test_unlisting_forgets_a_robot_never_heard_and_keeps_one_heard_as_discovered() -> None:
    fleet = Fleet(expire_after=60)
    fleet.model.set_inventory(Inventory({"never": TB4, "heard": TB4}))
    fleet.publish("heard", "/Power/Battery")
    fleet.check()
    fleet.take()
    fleet.model.set_inventory(Inventory({}))
    fleet.check()
    assert fleet.take() == [("unlisted", "never", None)]
    snapshot, robot = fleet.robot("heard")
    assert robot.listing is None and [key[0] for key in robot.components] == ["/Power/Battery"]
    assert snapshot.find("never") is None and snapshot.forgotten_counts == {"unlisted": 1}
    fleet.now += 61
    fleet.model.expire()  # no longer listed: silence forgets it as any discovered robot
    fleet.check()
    assert ("expired", "heard", None) in fleet.take()
    assert fleet.model.snapshot().forgotten_counts == {"unlisted": 1, "expired": 1}


def test_a_robot_remembered_from_before_a_restart_is_down_since_then_without_an_event() -> None:
    fleet = Fleet(robot_timeout=10, expire_after=86400)
    fleet.model.remember(
        [RememberedRobot("r1", "dds", START - 3600), RememberedRobot("r2", "dds", START - 2)]
    )
    fleet.check()
    snapshot, r1 = fleet.robot("r1")
    assert not snapshot.robot_up(r1)
    assert r1.last_message_wall == START - 3600 and r1.transport == "dds"
    assert snapshot.robot_up(fleet.robot("r2")[1])  # heard 2 s before: up, as it was
    assert fleet.take() == []
    fleet.now += 20  # r2 not heard since: it goes down as it would have
    fleet.check()
    assert fleet.take() == [("robot_down", "r2", None)]
    fleet.publish("r1", "/a")
    fleet.check()
    assert ("robot_up", "r1", None) in fleet.take()


def test_a_remembered_robot_speaking_within_its_timeout_continues_its_run() -> None:
    fleet = Fleet(robot_timeout=10)
    fleet.model.remember([RememberedRobot("r1", "dds", START - 2)])
    fleet.check()
    fleet.publish("r1", "/a")
    fleet.check()
    assert [event for event in fleet.take() if event[0].startswith("robot")] == []


def test_remembering_leaves_a_robot_heard_in_this_run_as_it_is_and_keeps_a_listing() -> None:
    fleet = Fleet()
    fleet.model.set_inventory(Inventory({"listed": TB4}))
    fleet.publish("heard", "/a")
    fleet.model.remember(
        [RememberedRobot("heard", "dds", START - 100), RememberedRobot("listed", "zenoh", 1.0)]
    )
    assert fleet.robot("heard")[1].last_message == START
    listed = fleet.robot("listed")[1]
    assert listed.listing == TB4 and listed.transport == "zenoh"
    assert all(is_stand_in(component) for component in listed.components.values())


def test_only_a_silent_unlisted_robot_can_be_retired_and_its_event_is_the_askers() -> None:
    fleet = Fleet(robot_timeout=10)
    fleet.model.set_inventory(Inventory({"listed": TB4}))
    fleet.publish("alive", "/a")
    fleet.publish("dead", "/a")
    fleet.check()
    fleet.now += 15
    fleet.publish("alive", "/a")
    fleet.now += 6  # past "dead"'s 15 s (heard once: three stale_after)
    assert [fleet.model.retire(name) for name in ("nobody", "listed", "alive")] == ["unknown", "listed", "up"]
    fleet.take()
    assert fleet.model.retire("dead") == "retired"
    fleet.check()
    assert [event for event in fleet.take() if event[1] == "dead" and event[0] != "robot_down"] == []
    snapshot = fleet.model.snapshot()
    assert snapshot.find("dead") is None
    assert snapshot.forgotten["dead"].reason == "retired" and snapshot.forgotten_counts == {"retired": 1}


def test_a_robot_forgotten_while_another_appears_still_has_its_event() -> None:
    fleet = Fleet(robot_timeout=10, expire_after=60)
    fleet.publish("old", "/a")
    fleet.check()
    fleet.now += 61
    fleet.model.expire()
    fleet.publish("new", "/a")  # as many robots as before: the detector must still see "old" gone
    fleet.check()
    assert ("expired", "old", None) in fleet.take()


def test_a_relisted_robot_keeps_its_record_when_its_entry_did_not_change() -> None:
    fleet = Fleet()
    fleet.model.set_inventory(Inventory({"r1": TB4}))
    before = fleet.robot("r1")[1]
    fleet.model.set_inventory(Inventory({"r1": ListedRobot(TB4.labels, TB4.expected)}))
    assert fleet.robot("r1")[1] is before
    fleet.model.set_inventory(Inventory({"r1": ListedRobot((("site", "b"),), ())}))
    after = fleet.robot("r1")[1]
    assert after.revision > before.revision and after.components == {}


def test_a_shard_lists_only_the_robots_it_owns() -> None:
    fleet = Fleet()
    fleet.model.set_inventory(Inventory({"a": TB4, "b": TB4}), owns=lambda name: name == "a")
    assert [robot.name for robot in fleet.model.snapshot().robots] == ["a"]


def test_robots_remembered_from_before_a_restart_share_their_components_keys() -> None:
    # A component reported again keeps the key it was restored with: a tuple each would be 56 bytes of
    # every component for as long as the exporter runs after a restart.
    before = Fleet(robot_timeout=10)
    for robot in ("r1", "r2"):
        before.publish(robot, "/Power/Battery", "/Motor", level=0)
    kept = before.model.heard(with_components=True)
    after = Fleet(robot_timeout=10)
    after.model.remember(kept)
    after.publish("r1", "/Power/Battery", "/Motor", level=1)
    first, second = after.model.snapshot().robots
    for name in ("/Power/Battery", "/Motor"):
        [key_1] = [key for key in first.components if key[0] == name]
        [key_2] = [key for key in second.components if key[0] == name]
        assert key_1 == (name, "") and key_1 is key_2 and first.components[key_1].key is key_2


def test_a_clean_stop_keeps_what_robots_reported_and_a_restart_carries_on_from_it() -> None:
    before = Fleet(robot_timeout=10)
    before.publish("r1", "/Power/Battery", "/Motor", level=1)
    before.now += 1
    [kept] = before.model.heard(with_components=True)
    assert kept.components == (("/Power/Battery", "hw", 1, "fine"), ("/Motor", "hw", 1, "fine"))
    assert before.model.heard()[0].components == ()  # only a clean stop pays for them
    after = Fleet(robot_timeout=10)
    after.now = before.now + 2  # restarted two seconds later
    after.model.remember([kept])
    after.check()
    assert after.components("r1") == {"/Power/Battery": (Level.WARN, "fine"), "/Motor": (Level.WARN, "fine")}
    assert after.model.snapshot().robot_level(after.robot("r1")[1]) is Level.WARN
    after.publish("r1", "/Power/Battery", "/Motor", level=1)  # heard again: the same components carry on
    after.check()
    assert after.take() == []
    after.publish("r1", "/Power/Battery", "/Motor", level=2)
    assert sorted(after.take()) == [("level", "r1", "/Motor"), ("level", "r1", "/Power/Battery")]


def test_a_robot_that_was_only_a_moved_feed_is_forgotten_as_reattributed_with_an_event() -> None:
    fleet = Fleet()
    fleet.publish("domain0", "drive: Motor")
    fleet.check()
    fleet.take()
    fleet.model.forget_feed("domain0", "writer", last=True)
    fleet.check()
    snapshot = fleet.model.snapshot()
    assert snapshot.find("domain0") is None
    assert snapshot.forgotten_counts == {"reattributed": 1}
    assert fleet.take() == [("reattributed", "domain0", None)]


def test_a_moved_feed_leaves_the_robots_other_feeds_and_a_listed_robot_goes_down_with_its_last() -> None:
    fleet = Fleet()
    fleet.model.set_inventory(Inventory({"listed": ListedRobot()}))
    fleet.publish("shared", "drive: Motor")
    fleet.model.apply(
        "shared", DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "Disk", "ok", "", ()),)), "dds", feed="other"
    )
    fleet.publish("listed", "drive: Motor")
    fleet.model.forget_feed("shared", "writer", last=False)
    fleet.model.forget_feed("listed", "writer", last=True)
    snapshot, shared = fleet.robot("shared")
    _, listed = fleet.robot("listed")
    assert list(fleet.components("shared")) == ["Disk"] and snapshot.robot_up(shared)
    assert fleet.components("listed") == {} and not snapshot.robot_up(listed)
    # A robot whose other publisher has said nothing yet is kept for it.
    fleet.publish("quiet", "drive: Motor")
    fleet.model.forget_feed("quiet", "writer", last=False)
    assert fleet.components("quiet") == {}
    # The other feed's publisher has left: what it said stays, and the robot is down.
    fleet.publish("shared", "drive: Motor")
    fleet.model.forget_feed("shared", "writer", last=True)
    snapshot, shared = fleet.robot("shared")
    assert list(fleet.components("shared")) == ["Disk"] and not snapshot.robot_up(shared)
    assert snapshot.forgotten_counts == {}
