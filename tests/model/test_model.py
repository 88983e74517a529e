"""The fleet model's semantics: staleness, robot up/down, expiry, caps and level changes."""

from __future__ import annotations

import re

from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.model.expiry import expiry_interval
from overseer.model.state import StaleOverride
from support.clock import ManualClock


def array(*statuses: DiagnosticStatus) -> DiagnosticArray:
    """A message carrying `statuses`."""
    return DiagnosticArray(0, 0, "", statuses)


def status(name: str, level: int = 0, hardware_id: str = "", **values: str) -> DiagnosticStatus:
    """A status with optional key-values."""
    return DiagnosticStatus(level, name, f"{name} says {level}", hardware_id, tuple(values.items()))


def make_model(**limits: float) -> tuple[FleetModel, ManualClock]:
    clock = ManualClock()
    return FleetModel(FleetLimits(**limits), clock=clock), clock  # type: ignore[arg-type]


def steady(
    model: FleetModel,
    clock: ManualClock,
    robot: str,
    *statuses: DiagnosticStatus,
    feed: str = "",
    period: float = 1.0,
) -> None:
    """The same array twice, `period` apart, on `feed`: the feed's period is known from then on."""
    model.apply(robot, array(*statuses), "dds", feed=feed)
    clock.now += period
    model.apply(robot, array(*statuses), "dds", feed=feed)


def levels(model: FleetModel) -> dict[str, Level]:
    """Component name → level now of the model's first robot."""
    snapshot = model.snapshot()
    robot = snapshot.robots[0]
    up = snapshot.robot_up(robot)
    return {key[0]: snapshot.component_level(robot, key, c, up) for key, c in robot.components.items()}


def test_components_keep_reported_level_message_and_values() -> None:
    model, _ = make_model()
    model.apply("r1", array(status("/Power/Battery", 1, "bms", voltage="11.2")), "dds")
    snapshot = model.snapshot()
    robot = snapshot.find("r1")
    assert robot is not None
    component = robot.components[("/Power/Battery", "")]
    assert (component.level, component.message, component.hardware_id, component.values) == (
        Level.WARN,
        "/Power/Battery says 1",
        "bms",
        (("voltage", "11.2"),),
    )
    assert snapshot.component_level(robot, ("/Power/Battery", ""), component, True) is Level.WARN


def test_robot_level_uses_severity_order() -> None:
    model, clock = make_model(stale_after=5, robot_timeout=30)
    steady(model, clock, "r1", status("/a", 1))
    clock.now += 6
    model.apply("r1", array(status("/b", 0)), "dds")  # /a is now stale, /b fresh
    snapshot = model.snapshot()
    robot = snapshot.find("r1")
    assert robot is not None
    assert snapshot.robot_level(robot) is Level.STALE
    model.apply("r1", array(status("/a", 1)), "dds")
    snapshot = model.snapshot()
    assert snapshot.robot_level(snapshot.robots[0]) is Level.WARN


def test_component_goes_stale_after_timeout() -> None:
    model, clock = make_model(stale_after=5, robot_timeout=60)
    steady(model, clock, "r1", status("/a", 0), status("/b", 2))
    clock.now += 5
    model.apply("r1", array(status("/a", 0)), "dds")
    clock.now += 0.5
    snapshot = model.snapshot()
    robot = snapshot.robots[0]
    up = snapshot.robot_up(robot)
    levels = {k[0]: snapshot.component_level(robot, k, c, up) for k, c in robot.components.items()}
    assert levels == {"/a": Level.OK, "/b": Level.STALE}


def test_silent_robot_is_down_with_every_component_stale() -> None:
    model, clock = make_model(stale_after=5, robot_timeout=10)
    steady(model, clock, "r1", status("/a", 2))
    clock.now += 10
    assert model.snapshot().robot_up(model.snapshot().robots[0])
    clock.now += 0.1
    snapshot = model.snapshot()
    robot = snapshot.robots[0]
    assert not snapshot.robot_up(robot)
    assert snapshot.robot_level(robot) is Level.STALE
    assert snapshot.component_level(robot, ("/a", ""), robot.components[("/a", "")], False) is Level.STALE


def test_robot_whose_publisher_left_is_down_at_once_and_up_only_with_a_message_after_it() -> None:
    model, clock = make_model(stale_after=5, robot_timeout=60)
    model.apply("r1", array(status("/a", 1)), "zenoh")
    clock.now += 1
    model.publisher_left("r1")
    snapshot = model.snapshot()
    robot = snapshot.robots[0]
    assert not snapshot.robot_up(robot) and not robot.publisher_alive
    assert snapshot.robot_level(robot) is Level.STALE
    clock.now += 1  # a new publisher appearing says nothing: only its data does
    assert not model.snapshot().robot_up(model.snapshot().robots[0])
    assert model.touch("r1", "zenoh")
    snapshot = model.snapshot()
    assert snapshot.robot_up(snapshot.robots[0]) and snapshot.robots[0].publisher_alive
    assert snapshot.robot_level(snapshot.robots[0]) is Level.WARN
    assert snapshot.robots[0].up_since == clock.now
    model.publisher_left("unknown")  # nothing to do, nothing created
    assert [r.name for r in model.snapshot().robots] == ["r1"]


def test_silent_robot_is_forgotten_after_expiry() -> None:
    model, clock = make_model(stale_after=5, robot_timeout=10, expire_after=60)
    model.apply("r1", array(status("/a")), "dds")
    model.apply("r2", array(status("/a")), "dds")
    clock.now += 30
    model.apply("r2", array(status("/a")), "dds")
    clock.now += 31
    assert model.expire() == ["r1"]
    assert [r.name for r in model.snapshot().robots] == ["r2"]


def test_vanished_component_is_forgotten_after_expiry() -> None:
    model, clock = make_model(stale_after=5, robot_timeout=10, expire_after=60)
    model.apply("r1", array(status("/old"), status("/kept")), "dds")
    clock.now += 61
    model.apply("r1", array(status("/kept")), "dds")
    model.expire()
    assert list(model.snapshot().robots[0].components) == [("/kept", "")]


def test_expiry_looks_often_enough_to_be_at_most_a_hundredth_late_and_no_more_than_that() -> None:
    assert expiry_interval(8) == 1.0  # a short expiry (the tests'): every second
    assert expiry_interval(3600) == 36.0  # an hour: at most 36 s late
    assert expiry_interval(7 * 86400) == 60.0  # the default week: once a minute, not 60 times as often


def test_discovered_robot_without_messages_is_down_until_it_speaks() -> None:
    model, _ = make_model()
    assert model.register("r1", "dds")
    snapshot = model.snapshot()
    assert not snapshot.robot_up(snapshot.robots[0])
    model.apply("r1", array(status("/a")), "dds")
    snapshot = model.snapshot()
    assert snapshot.robot_up(snapshot.robots[0])


def test_components_are_told_apart_by_hardware_id() -> None:
    model, _ = make_model()
    model.apply("r1", array(status("/Motor", 0, "left"), status("/Motor", 2, "right")), "dds")
    components = model.snapshot().robots[0].components
    assert {k: (c.level, c.hardware_id) for k, c in components.items()} == {
        ("/Motor", "left"): (Level.OK, "left"),
        ("/Motor", "right"): (Level.ERROR, "right"),
    }


def test_robots_reporting_one_name_share_one_key_and_a_name_kept_apart_gets_its_own() -> None:
    # A key tuple of its own for each component was 56 bytes of each (10,000 robots of 50 components).
    model, _ = make_model()
    for robot in ("r1", "r2"):
        # Built here, not interned by a decoder: the model shares what it is given.
        model.apply(robot, array(status("".join(["/", "Lidar"])), status("/Motor", 0, "left")), "dds")
    model.apply("r2", array(status("/Motor", 0, "left"), status("/Motor", 2, "right")), "dds")
    first, second = model.snapshot().robots
    [lidar_1] = [key for key in first.components if key[0] == "/Lidar"]
    [lidar_2] = [key for key in second.components if key[0] == "/Lidar"]
    assert lidar_1 == ("/Lidar", "") and lidar_1 is lidar_2
    assert second.components[lidar_2].key is lidar_2  # the component's own key is that same tuple
    assert list(first.components) == [("/Lidar", ""), ("/Motor", "")]
    assert list(second.components) == [("/Lidar", ""), ("/Motor", "left"), ("/Motor", "right")]


def test_level_changes_are_counted_per_component() -> None:
    model, _ = make_model()
    for level in (0, 0, 2, 2, 0, 1):
        model.apply("r1", array(status("/a", level), status("/b", 0)), "dds")
    components = model.snapshot().robots[0].components
    assert components[("/a", "")].level_changes == 3
    assert components[("/b", "")].level_changes == 0


def test_robot_cap_drops_and_counts() -> None:
    model, _ = make_model(max_robots=2)
    for name in ("r1", "r2", "r3"):
        model.apply(name, array(status("/a"), status("/b")), "dds")
    snapshot = model.snapshot()
    assert [r.name for r in snapshot.robots] == ["r1", "r2"]
    assert snapshot.message_counts[("dds", "dropped")] == 1
    assert snapshot.message_counts[("dds", "received")] == 2
    assert snapshot.dropped_statuses["robot_limit"] == 2
    assert not model.register("r4", "dds")


def test_component_cap_keeps_known_components_and_counts_the_rest() -> None:
    model, _ = make_model(max_components_per_robot=3)
    model.apply("r1", array(*(status(f"/c{i}") for i in range(5))), "dds")
    model.apply("r1", array(status("/c0", 2), status("/new")), "dds")
    snapshot = model.snapshot()
    components = snapshot.robots[0].components
    assert sorted(name for name, _ in components) == ["/c0", "/c1", "/c2"]
    assert components[("/c0", "")].level is Level.ERROR
    assert snapshot.dropped_statuses["component_limit"] == 3
    assert snapshot.message_counts[("dds", "dropped")] == 2


def test_long_strings_are_truncated_and_counted() -> None:
    model, _ = make_model(max_string_length=8)
    long = "x" * 1_000_000
    model.apply("r1", array(DiagnosticStatus(0, "/" + long, long, long, ((long, long), ("k", "v")))), "dds")
    snapshot = model.snapshot()
    component = next(iter(snapshot.robots[0].components.values()))
    assert component.name == "/xxxxxxx"
    assert len(component.message) == 8
    assert component.values == (("x" * 8, "x" * 8), ("k", "v"))
    assert snapshot.truncated_strings == 5


def test_values_beyond_cap_are_dropped_and_counted() -> None:
    model, _ = make_model(max_values_per_component=2)
    model.apply("r1", array(status("/a", 0, "", a="1", b="2", c="3")), "dds")
    snapshot = model.snapshot()
    assert next(iter(snapshot.robots[0].components.values())).values == (("a", "1"), ("b", "2"))
    assert snapshot.dropped_statuses["value_limit"] == 1


def test_invalid_level_drops_only_that_status() -> None:
    model, _ = make_model()
    model.apply("r1", array(status("/good", 1), DiagnosticStatus(7, "/bad", "", "", ())), "dds")
    snapshot = model.snapshot()
    assert list(snapshot.robots[0].components) == [("/good", "")]
    assert snapshot.dropped_statuses["invalid_level"] == 1


def test_forgetting_a_topic_removes_only_its_components() -> None:
    model, _ = make_model()
    model.apply("r1", array(status("raw: a")), "dds", "rt/r1/diagnostics")
    model.apply("r1", array(status("/Agg/a")), "dds", "rt/r1/diagnostics_agg")
    model.forget_topic("r1", "rt/r1/diagnostics")
    assert list(model.snapshot().robots[0].components) == [("/Agg/a", "")]


def test_snapshot_is_not_changed_by_later_messages() -> None:
    model, _ = make_model()
    model.apply("r1", array(status("/a", 0)), "dds")
    before = model.snapshot()
    model.apply("r1", array(status("/a", 2), status("/b", 1)), "dds")
    assert {k: c.level for k, c in before.robots[0].components.items()} == {("/a", ""): Level.OK}


def test_identical_message_refreshes_every_component_it_carries() -> None:
    model, clock = make_model(stale_after=5, robot_timeout=60)
    model.apply("r1", array(status("/a", 1), status("/b", 2)), "dds")
    clock.now += 4
    model.apply("r1", array(status("/a", 1)), "dds")  # /b left the message
    for _ in range(3):
        clock.now += 4
        assert model.touch("r1", "dds")
    snapshot = model.snapshot()
    robot = snapshot.robots[0]
    levels = {k[0]: snapshot.component_level(robot, k, c, True) for k, c in robot.components.items()}
    assert levels == {"/a": Level.WARN, "/b": Level.STALE}
    assert snapshot.last_update(robot, ("/a", ""), robot.components[("/a", "")]) == clock.now
    assert snapshot.last_update(robot, ("/b", ""), robot.components[("/b", "")]) == clock.now - 16
    assert snapshot.message_counts[("dds", "received")] == 5


def test_touching_an_unknown_robot_asks_for_a_full_apply() -> None:
    model, _ = make_model()
    assert not model.touch("r1", "dds")
    model.register("r1", "dds")
    assert not model.touch("r1", "dds")


def test_unchanged_components_keep_their_record() -> None:
    model, _ = make_model()
    model.apply("r1", array(status("/a", 0, "", v="1"), status("/b", 0)), "dds")
    before = model.snapshot().robots[0].components
    model.apply("r1", array(status("/a", 0, "", v="2"), status("/b", 0)), "dds")
    after = model.snapshot().robots[0].components
    assert after[("/b", "")] is before[("/b", "")]
    assert after[("/a", "")].values == (("v", "2"),)


def test_a_start_up_status_without_hardware_id_and_the_real_one_are_one_component() -> None:
    # diagnostic_updater's add(): "<node>: <task>" / "Node starting up" with no hardware_id, then the task.
    model, clock = make_model()
    model.apply("r1", array(DiagnosticStatus(0, "drive: Motor", "Node starting up", "", ())), "dds")
    clock.now += 0.2
    model.apply("r1", array(status("drive: Motor", 2, "m1"), status("drive: Other", 0, "m1")), "dds")
    clock.now += 1
    # broadcast() and a later start-up send no hardware_id either: the component keeps the one it had
    model.apply("r1", array(DiagnosticStatus(1, "drive: Motor", "shutting down", "", ())), "dds")
    components = model.snapshot().robots[0].components
    assert list(components) == [("drive: Motor", ""), ("drive: Other", "")]
    motor = components[("drive: Motor", "")]
    assert (motor.level, motor.message, motor.hardware_id, motor.level_changes) == (
        Level.WARN,
        "shutting down",
        "m1",
        2,
    )


def test_a_changed_hardware_id_is_the_same_component_under_its_new_id() -> None:
    model, _ = make_model()
    model.apply("r1", array(status("/Lidar", 0, "serial-1")), "dds")
    model.apply("r1", array(status("/Lidar", 0, "serial-2")), "dds")
    [(key, lidar)] = model.snapshot().robots[0].components.items()
    assert key == ("/Lidar", "") and lidar.hardware_id == "serial-2"


def test_one_name_with_two_hardware_ids_in_one_array_is_kept_apart_from_then_on() -> None:
    model, _ = make_model()
    model.apply("r1", array(status("/Motor", 0, "left")), "dds")
    model.apply("r1", array(status("/Motor", 0, "left"), status("/Motor", 2, "right")), "dds")
    assert list(model.snapshot().robots[0].components) == [("/Motor", "left"), ("/Motor", "right")]
    model.apply("r1", array(status("/Motor", 1, "right")), "dds")  # alone again, still apart
    model.apply("r1", array(DiagnosticStatus(1, "/Motor", "no id", "", ())), "dds")  # goes to the first
    components = model.snapshot().robots[0].components
    assert list(components) == [("/Motor", "left"), ("/Motor", "right")]
    assert components[("/Motor", "left")].message == "no id"
    assert components[("/Motor", "right")].level is Level.WARN


def test_nodes_sharing_a_robots_topic_each_keep_their_components_fresh() -> None:
    # Two diagnostic_updater nodes on one robot's /diagnostics: each array holds its own statuses only.
    model, clock = make_model(stale_after=5, robot_timeout=60)
    for _ in range(30):
        model.apply("r1", array(status("drive: Motor", 0)), "dds", "rt/diagnostics", "rt/diagnostics@drive")
        model.apply(
            "r1", array(status("camera: Frames", 1)), "dds", "rt/diagnostics", "rt/diagnostics@camera"
        )
        clock.now += 1
    snapshot = model.snapshot()
    robot = snapshot.robots[0]
    assert levels(model) == {"drive: Motor": Level.OK, "camera: Frames": Level.WARN}
    assert [(feed.name, feed.period) for feed in robot.feeds] == [
        ("rt/diagnostics@drive", 1.0),
        ("rt/diagnostics@camera", 1.0),
    ]
    assert not robot.missing
    for _ in range(6):  # the camera node stops; the drive node goes on
        assert model.touch("r1", "dds", "rt/diagnostics@drive")
        clock.now += 1
    assert levels(model) == {"drive: Motor": Level.OK, "camera: Frames": Level.STALE}


def test_a_slow_producer_is_stale_after_three_of_its_periods_not_after_stale_after() -> None:
    # ntp_monitor publishes every 10 s when its NTP requests time out.
    model, clock = make_model(stale_after=5, robot_timeout=10)
    for _ in range(3):
        model.apply("r1", array(status("NTP offset", 2)), "dds")
        for _ in range(10):  # judged every second between two messages: never STALE, robot never down
            clock.now += 1
            snapshot = model.snapshot()
            assert snapshot.robot_up(snapshot.robots[0])
            assert levels(model) == {"NTP offset": Level.ERROR}
    robot = model.snapshot().robots[0]
    assert robot.feeds[0].period == 10.0
    model.apply("r1", array(status("NTP offset", 2)), "dds")
    clock.now += 30  # it stops: STALE and down after three periods, 30 s
    assert levels(model) == {"NTP offset": Level.ERROR}
    clock.now += 0.1
    snapshot = model.snapshot()
    assert levels(model) == {"NTP offset": Level.STALE}
    assert not snapshot.robot_up(snapshot.robots[0])


def test_a_producers_period_is_not_spoiled_by_start_up_arrays_or_forced_updates() -> None:
    model, clock = make_model(stale_after=5, robot_timeout=10)
    for name in ("n: a", "n: b", "n: c"):  # add() of three tasks: a one-status array each, at once
        model.apply("r1", array(DiagnosticStatus(0, name, "Node starting up", "", ())), "dds")
        clock.now += 0.001
    whole = array(status("n: a"), status("n: b"), status("n: c"))
    for _ in range(4):
        clock.now += 10
        model.apply("r1", whole, "dds")
    clock.now += 0.01  # force_update() right after an update
    model.apply("r1", whole, "dds")
    assert model.snapshot().robots[0].feeds[0].period == 10.0
    clock.now += 25
    assert set(levels(model).values()) == {Level.OK}


def test_a_producer_heard_once_is_given_three_times_stale_after() -> None:
    model, clock = make_model(stale_after=5, robot_timeout=10)
    model.apply("r1", array(status("/a")), "dds")
    clock.now += 15
    assert levels(model) == {"/a": Level.OK}
    snapshot = model.snapshot()
    assert snapshot.robot_up(snapshot.robots[0])
    clock.now += 0.1
    assert levels(model) == {"/a": Level.STALE}


def test_an_override_sets_the_stale_bound_of_the_components_its_pattern_matches() -> None:
    overrides = (StaleOverride(re.compile("NTP.*"), 60.0), StaleOverride(re.compile("fast: .*"), 2.0))
    model, clock = make_model(stale_after=5, robot_timeout=600, stale_overrides=overrides)  # type: ignore[arg-type]
    steady(model, clock, "r1", status("NTP offset"), status("fast: imu"), status("other"))
    clock.now += 2.5
    assert levels(model) == {"NTP offset": Level.OK, "fast: imu": Level.STALE, "other": Level.OK}
    clock.now += 55
    assert levels(model) == {"NTP offset": Level.OK, "fast: imu": Level.STALE, "other": Level.STALE}
    clock.now += 3
    assert levels(model) == {"NTP offset": Level.STALE, "fast: imu": Level.STALE, "other": Level.STALE}


def test_a_restarted_node_takes_its_components_over_and_its_old_feed_goes() -> None:
    model, clock = make_model()
    steady(model, clock, "r1", status("drive: a"), status("drive: b"), feed="old-writer")
    clock.now += 1
    model.apply("r1", array(DiagnosticStatus(0, "drive: a", "Node starting up", "", ())), "dds", feed="new")
    robot = model.snapshot().robots[0]
    assert [feed.name for feed in robot.feeds] == ["old-writer", "new"]
    assert robot.feeds[0].latest == (None, ("drive: b", ""))  # the old one reads its next message whole
    clock.now += 1
    model.apply("r1", array(status("drive: a"), status("drive: b")), "dds", feed="new")
    robot = model.snapshot().robots[0]
    assert [feed.name for feed in robot.feeds] == ["new"]
    assert {c.feed for c in robot.components.values()} == {"new"} and not robot.missing
    assert not model.touch("r1", "dds", "old-writer")


def test_a_step_of_the_wall_clock_changes_no_judgement_only_the_dates_reported() -> None:
    monotonic, wall = ManualClock(), ManualClock()
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=10), clock=monotonic, wall_clock=wall)
    for _ in range(3):
        model.apply("r1", array(status("/a", 1)), "dds")
        monotonic.now += 1
        wall.now += 1
    before = model.snapshot()
    for step in (120.0, -3600.0):
        wall.now += step  # NTP steps the clock, or a VM resumes
        snapshot = model.snapshot()
        robot = snapshot.robots[0]
        assert snapshot.robot_up(robot) and snapshot.robot_level(robot) is Level.WARN
        assert robot.last_message_wall == before.robots[0].last_message_wall  # dated when it arrived
    model.apply("r1", array(status("/a", 1)), "dds")
    assert model.snapshot().robots[0].last_message_wall == wall.now


def test_feeds_beyond_the_cap_are_dropped_and_counted() -> None:
    model, _ = make_model(max_feeds_per_robot=2)
    for feed in ("w1", "w2", "w3"):
        model.apply("r1", array(status(f"/{feed}")), "dds", feed=feed)
    snapshot = model.snapshot()
    assert [feed.name for feed in snapshot.robots[0].feeds] == ["w1", "w2"]
    assert snapshot.dropped_statuses["feed_limit"] == 1


def test_one_robots_snapshot_holds_that_robot_as_the_fleets_snapshot_judges_it() -> None:
    model, clock = make_model(stale_after=5.0, robot_timeout=10.0)
    steady(model, clock, "r1", status("/a", 1), status("/b", 0))
    steady(model, clock, "r2", status("/c", 2))
    clock.now += 7.0  # r1's and r2's components STALE by now, the robots still up
    model.apply("r2", array(status("/c", 2)), "dds")

    whole = model.snapshot()
    for name in ("r1", "r2"):
        alone = model.robots_snapshot((name,))
        assert [robot.name for robot in alone.robots] == [name]
        robot = alone.robots[0]
        assert robot is whole.find(name)
        assert alone.robot_up(robot) == whole.robot_up(robot)
        assert alone.component_levels(robot, True) == whole.component_levels(robot, True)
    assert model.robots_snapshot(("r3",)).robots == ()
    named = model.robots_snapshot(["r2", "r3", "r1"])  # the push's few robots: the known ones, in that order
    assert [robot.name for robot in named.robots] == ["r2", "r1"]
    assert all(robot is whole.find(robot.name) for robot in named.robots)
