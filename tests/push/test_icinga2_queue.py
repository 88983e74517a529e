"""The push in process, with no Icinga 2: a fleet part failing half-way through a look; a stage's text.

No Icinga 2 answers here (the push's URL is a closed loopback port): what is looked at is what the push
queues and what it holds, not what it delivers, which the tests beside this one follow into a real Icinga 2.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from threading import Event

import pytest

from overseer.config.icinga2 import Icinga2Config
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.push import icinga2_objects, icinga2_push
from overseer.push.icinga2_client import Icinga2Client, Icinga2Error
from overseer.push.icinga2_package import object_text
from overseer.push.icinga2_push import Icinga2Push
from overseer.push.icinga2_results import CheckResult, ResultKey
from support.clock import ManualClock
from support.garbage import left_in_cycles
from support.push_fleet import FleetFailingOnce
from testbed.ports import free_port

ROBOTS = [f"robot{index}" for index in range(10)]
SERVICES = frozenset({"ros-diagnostics", "ros-diagnostics-Power"})  # a robot's, with one group


def unreachable_config() -> Icinga2Config:
    """A push configuration whose Icinga 2 is a loopback port nothing listens on."""
    port = free_port()
    return Icinga2Config(
        url=f"https://127.0.0.1:{port}", host="127.0.0.1", port=port, ca_file="", password="p"
    )


def queued_hosts(push: Icinga2Push) -> list[str]:
    """The hosts of the results the push holds, one entry a host result (each robot's once)."""
    return [host for host, service in [*push._urgent, *push._pending] if not service]


def test_a_part_failing_half_way_through_a_look_leaves_the_robots_not_reached_for_the_next(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(icinga2_push, "SNAPSHOT_ROBOTS", 4)  # 10 robots: asked 4, 4 and 2 at a time
    clock = ManualClock(1000.0)
    model = FleetModel(FleetLimits(stale_after=60, robot_timeout=120), clock=clock)
    for robot in ROBOTS:
        model.apply(
            robot, DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/Power/Battery", "ok", "", ()),)), "dds"
        )
    fleet = FleetFailingOnce(model, fail_at=2)
    # Every delivery fails and waits its backoff: what is looked at is the queue.
    push = Icinga2Push(unreachable_config(), fleet, expire_after=3600.0, clock=clock)  # type: ignore[arg-type]

    push.step()  # the first 4 robots queued, then the second ask fails: the look stops there
    first = queued_hosts(push)
    assert len(first) == 4 and set(first) == fleet.asked[0]
    assert not push._objects._to_delete  # a partial look forgets no robot

    clock.now += 1.0
    push.step()  # the next look asks for the 6 robots the first did not reach, and only for them
    assert set().union(*fleet.asked[2:]) == set(ROBOTS) - set(first)
    assert sorted(queued_hosts(push)) == sorted(ROBOTS)  # every robot queued once
    assert not push._objects._to_delete


def test_a_stages_object_texts_are_let_go_before_icinga_validates_it(monkeypatch: pytest.MonkeyPatch) -> None:
    made: list[str] = []  # every object's text, as object_text gave it

    def recorded(*args: object, **kwargs: object) -> str:
        text = object_text(*args, **kwargs)  # type: ignore[arg-type]
        made.append(text)
        return text

    def references() -> list[int]:
        return [sys.getrefcount(piece) for piece in made]

    held: list[int] = []

    class Package:
        """A config package that, as Icinga validates and loads a stage, counts who holds the texts."""

        name = "overseer-test"

        def deploy(self, text: str, loaded: Callable[[], bool]) -> None:
            """Count the references to each object's text while the stage would be loading."""
            held.extend(references())

    monkeypatch.setattr(icinga2_objects, "object_text", recorded)
    model = FleetModel(FleetLimits(), clock=ManualClock())
    push = Icinga2Push(unreachable_config(), FleetFailingOnce(model, 0), 3600.0)  # type: ignore[arg-type]
    push._objects._package = Package()  # type: ignore[assignment]
    push._objects._deploy(
        {f"robot{index}": {"ros-diagnostics", "ros-diagnostics-Power"} for index in range(3)}, lambda: True
    )
    # Counted the same way once the push let go of everything: a list of them all (30 MB at 10,000 robots)
    # held through the deploy would be one reference more.
    assert len(held) == 9 and held == references()


def robots_model(clock: ManualClock) -> FleetModel:
    """ROBOTS, each with one component in group Power, OK."""
    model = FleetModel(FleetLimits(stale_after=600, robot_timeout=1200), clock=clock)
    for robot in ROBOTS:
        model.apply(robot, power_array(0), "dds")
    return model


def power_array(level: int, message: str = "state") -> DiagnosticArray:
    """An array with one component, /Power/Battery, at `level`."""
    return DiagnosticArray(0, 0, "", (DiagnosticStatus(level, "/Power/Battery", message, "", ()),))


def delivered(push: Icinga2Push) -> dict[ResultKey, CheckResult]:
    """Empty the push's queue as a delivery would, and what it held (urgent first)."""
    held = {**push._urgent, **push._pending}
    push._urgent.clear()
    push._pending.clear()
    return held


def test_robots_beyond_the_queue_are_owed_their_results_and_registered_with_the_rest(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(icinga2_push, "QUEUED_RESULTS", 6)  # two robots: a host, robot, Power result each
    clock = ManualClock(1000.0)
    model = robots_model(clock)
    push = Icinga2Push(unreachable_config(), FleetFailingOnce(model, 0), 3600.0, clock=clock)  # type: ignore[arg-type]

    push.step()
    assert queued_hosts(push) == ["robot0", "robot1"]
    assert list(push._owed) == ROBOTS[2:]
    assert push.stats.read()[2] == 30  # every robot's results wait, built or not
    # As found in an empty Icinga: every robot's objects are wanted in the first stage.
    push._objects._created = {}
    wanted = push._objects.unmade_wanted(push._wanted_keys())
    assert wanted == {robot: {"ros-diagnostics", "ros-diagnostics-Power"} for robot in ROBOTS}

    # An owed robot's message changes (its level does not, so no look asks for it): its results, built
    # once there is room, come from the fleet then, not from the look that owed them.
    model.apply("robot9", power_array(0, "charging"), "dds")
    sent: dict[ResultKey, CheckResult] = {}
    hosts: list[str] = []
    while push._urgent or push._pending:
        held = delivered(push)
        hosts.extend(host for host, service in held if not service)
        sent.update(held)
        push.step()  # at the same moment: no robot's repeat is due yet
    assert hosts == ROBOTS and not push._owed  # each robot's results built once, in the order heard
    assert "charging" in sent[("robot9", "ros-diagnostics")].plugin_output
    assert "charging" not in sent[("robot1", "ros-diagnostics")].plugin_output


def test_a_robot_whose_level_changed_goes_before_owed_repeats(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(icinga2_push, "QUEUED_RESULTS", 6)
    clock = ManualClock(1000.0)
    model = robots_model(clock)
    push = Icinga2Push(unreachable_config(), FleetFailingOnce(model, 0), 3600.0, clock=clock)  # type: ignore[arg-type]
    push.step()
    while push._urgent or push._pending:
        delivered(push)
        push.step()
    clock.now += 2 * push._config.interval  # every robot's repeat due at once: two built, eight owed
    push.step()
    assert len(push._pending) == 6 and not push._urgent and not any(push._owed.values())
    delivered(push)
    model.apply("robot8", power_array(2), "dds")
    push.step()  # robot8's change first, then the first owed repeat: the queue is full again
    assert [host for host, service in push._urgent if not service] == ["robot8"]
    assert push._urgent[("robot8", "ros-diagnostics")].exit_status == 2
    assert [host for host, service in push._pending if not service] == ["robot2"]
    assert "robot8" not in push._owed and list(push._owed) == [
        "robot3",
        "robot4",
        "robot5",
        "robot6",
        "robot7",
        "robot9",
    ]


def test_a_robot_changing_at_every_look_is_sent_while_a_backlog_lasts(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(icinga2_push, "QUEUED_RESULTS", 6)
    clock = ManualClock(1000.0)
    model = robots_model(clock)
    push = Icinga2Push(unreachable_config(), FleetFailingOnce(model, 0), 3600.0, clock=clock)  # type: ignore[arg-type]
    queued_with_robot9 = 0
    for tick in range(30):
        clock.now += push._config.interval  # every robot's repeat due at every look: the backlog lasts
        model.apply("robot9", power_array(2 * (tick % 2)), "dds")  # and robot9's level changes each time
        push.step()
        queued_with_robot9 += ("robot9", "") in push._urgent
        for key in [*push._urgent, *push._pending][:4]:  # four results delivered a tick, urgent first
            push._urgent.pop(key, None) or push._pending.pop(key)
    # Owed repeats filling the room before each look would leave robot9 owed at every look, never sent.
    assert queued_with_robot9 >= 20


def test_a_robot_forgotten_while_owed_leaves_nothing_behind(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(icinga2_push, "QUEUED_RESULTS", 6)
    clock = ManualClock(1000.0)
    fleet = FleetFailingOnce(robots_model(clock), 0)
    push = Icinga2Push(unreachable_config(), fleet, 3600.0, clock=clock)  # type: ignore[arg-type]
    push.step()
    assert "robot5" in push._owed
    fleet.forgotten.add("robot5")
    push.step()
    state = (push._owed, push._signatures, push._due, push._groups, push._robot_hosts)
    assert all("robot5" not in held for held in state) and push._objects._to_delete == {"robot5"}
    assert push.stats.read()[2] == 27  # nine robots' three results, built or owed
    delivered(push)
    push._objects._created = {}
    assert "robot5" not in push._objects.unmade_wanted(push._wanted_keys())


def test_a_request_icinga_does_not_answer_leaves_no_reference_cycle() -> None:
    client = Icinga2Client(unreachable_config())
    # The failure named by a local of the frame its traceback holds kept every caller's frame alive: a
    # deploy's, with the stage's whole text (30 MB at 10,000 robots), for each retry while Icinga reloaded.
    assert left_in_cycles(lambda: client.request("GET", "/v1/status"), Icinga2Error) == []


def test_a_delivery_icinga_does_not_answer_leaves_no_reference_cycle() -> None:
    clock = ManualClock(1000.0)
    push = Icinga2Push(unreachable_config(), FleetFailingOnce(robots_model(clock), 0), 3600.0, clock=clock)  # type: ignore[arg-type]
    push.step()  # the results queued; Icinga not reached
    push._objects._created = {
        robot: frozenset({"ros-diagnostics", "ros-diagnostics-Power"}) for robot in ROBOTS
    }
    batch = list(push._urgent.items())  # every object made: the results go in one pipelined write
    assert left_in_cycles(lambda: push._push(batch, push._urgent, clock.now + 60), Icinga2Error) == []
    assert len(push._urgent) == 30  # none delivered, none lost


def test_a_change_still_queued_when_its_robot_is_owed_keeps_it_urgent(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(icinga2_push, "QUEUED_RESULTS", 6)
    clock = ManualClock(1000.0)
    push = Icinga2Push(unreachable_config(), FleetFailingOnce(robots_model(clock), 0), 3600.0, clock=clock)  # type: ignore[arg-type]
    push.step()  # robot0 and robot1 heard: their results queued as urgent, and Icinga does not take them
    assert ("robot0", "") in push._urgent
    # Due again, the queue still full: owed, its queued results dropped.
    clock.now += 2 * push._config.interval
    push.step()
    assert push._owed["robot0"] is True  # owed as a repeat, it would wait behind every change


def test_robots_with_the_same_groups_hold_one_set_of_them() -> None:
    clock = ManualClock(1000.0)
    model = robots_model(clock)
    model.apply(
        "robot9", DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/Motor/Left", "ok", "", ()),)), "dds"
    )
    push = Icinga2Push(unreachable_config(), FleetFailingOnce(model, 0), 3600.0, clock=clock)  # type: ignore[arg-type]
    push.step()
    # A set of strings a robot was 24 MB at 10,000 robots: nine robots in Power share one, robot9 its own.
    assert len({id(groups) for groups in push._groups.values()}) == 2
    assert push._groups["robot9"] == {"Power", "Motor"} and push._groups["robot0"] == {"Power"}


class HeldPackage:
    """A config package whose stages Icinga validates and loads until the test lets them end."""

    name = "overseer-test"

    def __init__(self) -> None:
        """No stage deployed yet."""
        self.release = Event()
        self.texts: list[str] = []

    def deploy(self, text: str, loaded: Callable[[], bool]) -> None:
        """Keep the stage's text; end once released."""
        self.texts.append(text)
        assert self.release.wait(30), "the test never let the stage end"


def push_beside_a_held_stage(
    monkeypatch: pytest.MonkeyPatch, clock: ManualClock
) -> tuple[Icinga2Push, HeldPackage]:
    """A push whose first five robots are registered, and whose stages are held; Icinga is not reached."""
    monkeypatch.setattr(icinga2_objects, "BULK_OBJECTS", 10)  # the other five robots' 15 objects: a stage
    push = Icinga2Push(unreachable_config(), FleetFailingOnce(robots_model(clock), 0), 3600.0, clock=clock)  # type: ignore[arg-type]
    package = HeldPackage()
    push._objects._package = package  # type: ignore[assignment]
    push._objects._created = {robot: SERVICES for robot in ROBOTS[:5]}  # as found in Icinga
    push._objects._packaged = dict(push._objects._created)
    return push, package


def test_while_a_stage_is_deployed_robots_it_registers_wait_for_it_and_icinga_away_is_a_reload_for_a_while(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = ManualClock(1000.0)
    push, package = push_beside_a_held_stage(monkeypatch, clock)
    try:
        push.step()
        assert push._objects.stage_in_flight and len(package.texts) == 1 and '"robot9"' in package.texts[0]
        # The registered robots' results go (and stay queued, unanswered); the others wait for the stage.
        assert sorted(queued_hosts(push)) == ROBOTS[:5] and sorted(push._owed) == ROBOTS[5:]
        # Icinga's API away while it reloads to run a stage: no failure counted, no backoff.
        assert push.stats.read()[0] == {"ok": 0} and push._retry.backoff == 1.0
        asks = len(push._fleet.asked)  # type: ignore[attr-defined]
        clock.now += 1.0
        push.step()  # the robots waiting for the stage are not asked for again
        assert push._fleet.asked[asks:] == []  # type: ignore[attr-defined]
        assert sorted(queued_hosts(push)) == ROBOTS[:5] and sorted(push._owed) == ROBOTS[5:]
        assert push.stats.read()[0] == {"ok": 0}
        clock.now += 31.0
        push.step()  # away for longer than a reload: a failure
        assert push.stats.read()[0] == {"ok": 0, "connection": 1} and push._retry.backoff == 2.0
    finally:
        package.release.set()
        assert push._objects._stage is not None
        push._objects._stage.join(5)
    clock.now += 10.0
    push.step()  # the stage's end taken into account: its robots registered
    assert not push._objects.stage_in_flight and set(push._objects.created) == set(ROBOTS)
    assert push.stats.stages() == {"ok": 1}
    assert push.stats.read()[0] == {"ok": 0, "connection": 2}  # no stage now: Icinga away is a failure
    clock.now += 1.0
    push.step()  # and their results built
    assert sorted(queued_hosts(push)) == ROBOTS and not push._owed


def test_a_forgotten_robot_of_the_package_waits_for_the_stage_being_deployed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = ManualClock(1000.0)
    push, package = push_beside_a_held_stage(monkeypatch, clock)
    objects = push._objects
    keys = [(robot, service) for robot in ROBOTS for service in ("", *SERVICES)]
    assert not objects.register_in_bulk(keys, clock.now)  # the other five robots' stage, deployed
    objects._to_delete = {"robot0", "robot9"}  # one of the package, one of the stage
    try:
        objects.delete_forgotten(clock.now)  # nothing: a stage without them now would race the one deployed
        assert objects._to_delete == {"robot0", "robot9"} and len(package.texts) == 1
    finally:
        package.release.set()
        assert objects._stage is not None
        objects._stage.join(5)
    assert objects.register_in_bulk(keys, clock.now) and "robot9" in objects._packaged
    objects.delete_forgotten(clock.now)  # now they go, with a stage of the package without them
    assert (
        len(package.texts) == 2 and '"robot0"' not in package.texts[1] and '"robot9"' not in package.texts[1]
    )
    assert '"robot1"' in package.texts[1] and '"robot8"' in package.texts[1]
    assert not objects._to_delete and set(objects.created) == set(ROBOTS) - {"robot0", "robot9"}
