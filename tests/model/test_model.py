"""The fleet model's semantics: staleness, robot up/down, expiry, caps and level changes."""

from __future__ import annotations

from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel


class ManualClock:
    """A clock the test moves by hand (the model's only notion of time)."""

    def __init__(self) -> None:
        """Start at an arbitrary unix time."""
        self.now = 1_700_000_000.0

    def __call__(self) -> float:
        """The current time."""
        return self.now


def array(*statuses: DiagnosticStatus) -> DiagnosticArray:
    """A message carrying `statuses`."""
    return DiagnosticArray(0, 0, "", statuses)


def status(name: str, level: int = 0, hardware_id: str = "", **values: str) -> DiagnosticStatus:
    """A status with optional key-values."""
    return DiagnosticStatus(level, name, f"{name} says {level}", hardware_id, tuple(values.items()))


def make_model(**limits: float) -> tuple[FleetModel, ManualClock]:
    clock = ManualClock()
    return FleetModel(FleetLimits(**limits), clock=clock), clock  # type: ignore[arg-type]


def test_components_keep_reported_level_message_and_values() -> None:
    model, _ = make_model()
    model.apply("r1", array(status("/Power/Battery", 1, "bms", voltage="11.2")), "dds")
    snapshot = model.snapshot()
    robot = snapshot.find("r1")
    assert robot is not None
    component = robot.components[("/Power/Battery", "bms")]
    assert (component.level, component.message, component.values) == (
        Level.WARN,
        "/Power/Battery says 1",
        (("voltage", "11.2"),),
    )
    assert snapshot.component_level(robot, ("/Power/Battery", "bms"), component, True) is Level.WARN


def test_robot_level_uses_severity_order() -> None:
    model, clock = make_model(stale_after=5, robot_timeout=30)
    model.apply("r1", array(status("/a", 1)), "dds")
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
    model.apply("r1", array(status("/a", 0), status("/b", 2)), "dds")
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
    model.apply("r1", array(status("/a", 2)), "dds")
    clock.now += 10
    assert model.snapshot().robot_up(model.snapshot().robots[0])
    clock.now += 0.1
    snapshot = model.snapshot()
    robot = snapshot.robots[0]
    assert not snapshot.robot_up(robot)
    assert snapshot.robot_level(robot) is Level.STALE
    assert snapshot.component_level(robot, ("/a", ""), robot.components[("/a", "")], False) is Level.STALE


def test_robot_whose_publisher_is_gone_is_down_at_once_and_up_when_it_returns() -> None:
    model, _ = make_model(stale_after=5, robot_timeout=60)
    model.apply("r1", array(status("/a", 1)), "zenoh")
    model.set_publisher_alive("r1", False)
    snapshot = model.snapshot()
    robot = snapshot.robots[0]
    assert not snapshot.robot_up(robot)
    assert snapshot.robot_level(robot) is Level.STALE
    model.apply("r1", array(status("/a", 1)), "zenoh")  # a message does not overrule the liveliness
    model.touch("r1", "zenoh")
    assert not model.snapshot().robot_up(model.snapshot().robots[0])
    model.set_publisher_alive("r1", True)
    snapshot = model.snapshot()
    assert snapshot.robot_up(snapshot.robots[0])
    assert snapshot.robot_level(snapshot.robots[0]) is Level.WARN
    model.set_publisher_alive("unknown", False)  # nothing to do, nothing created
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
    assert {k: c.level for k, c in components.items()} == {
        ("/Motor", "left"): Level.OK,
        ("/Motor", "right"): Level.ERROR,
    }


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
