"""`fleet.max_robots` across several models: the ingest workers count their robots in shared memory.

A worker's share of the cap would refuse robots while the fleet is under it, whenever the hash put more
than a share's worth in one worker; counted together, the fleet takes exactly the cap, in any split,
gives a robot's place back whichever way it is forgotten, and two workers taking the last place at the
same moment do not both take it.
"""

from __future__ import annotations

from collections.abc import Callable
from multiprocessing.connection import Connection, Pipe

from overseer.fleet.workers.launch import start_child
from overseer.fleet.workers.shared_counts import SharedCounts
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel, Inventory, ListedRobot
from overseer.model.robot_cap import SharedRobotCap
from support.clock import ManualClock

RACED_ROBOTS = 5_000  # each process tries to take this many
RACED_CAP = 6_000  # of their 10,000


def an_array() -> DiagnosticArray:
    """One OK status."""
    return DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/a", "ok", "", ()),))


def shared_models(cap: int, workers: int, clock: ManualClock | None = None) -> list[FleetModel]:
    """`workers` models counting their robots together against `cap`."""
    counts = SharedCounts.create(workers).slots
    limits = FleetLimits(max_robots=cap, expire_after=60)
    return [FleetModel(limits, clock, robot_cap=SharedRobotCap(cap, counts, slot)) for slot in range(workers)]


def test_robots_all_in_one_worker_fill_the_whole_cap_and_no_more() -> None:
    first, second = shared_models(3, 2)
    for name in ("r1", "r2", "r3"):  # all hashed to one worker: its half of the cap would keep one
        assert first.apply(name, an_array(), "dds")
    assert not second.apply("r4", an_array(), "dds")
    assert not second.register("r5", "dds")
    assert not first.apply("r6", an_array(), "dds")
    assert [robot.name for robot in first.snapshot().robots] == ["r1", "r2", "r3"]
    assert second.snapshot().robots == ()
    assert second.snapshot().dropped_statuses["robot_limit"] == 2  # r4's one status, and r5
    assert first.snapshot().dropped_statuses["robot_limit"] == 1


def test_a_robot_forgotten_in_one_worker_makes_room_in_another() -> None:
    clock = ManualClock(1_000.0)
    first, second = shared_models(2, 2, clock)
    first.apply("r1", an_array(), "dds")
    second.apply("r2", an_array(), "dds")
    assert not second.apply("r3", an_array(), "dds")
    clock.now += 61
    second.apply("r2", an_array(), "dds")  # r2 speaks on; r1 falls silent
    assert first.expire() == ["r1"]
    assert second.apply("r3", an_array(), "dds")
    assert [robot.name for robot in second.snapshot().robots] == ["r2", "r3"]


def test_a_worker_started_again_counts_its_robots_from_none() -> None:
    counts = SharedCounts.create(2).slots
    counts[0], counts[1] = 5, 1  # the dead worker's robots, and another worker's
    limits = FleetLimits(max_robots=6)
    restarted = FleetModel(limits, robot_cap=SharedRobotCap(6, counts, 0))
    for index in range(5):
        assert restarted.apply(f"r{index}", an_array(), "dds")
    assert not restarted.apply("r5", an_array(), "dds")
    assert counts.tolist() == [5, 1]


def test_a_retired_or_unlisted_robot_gives_its_place_back() -> None:
    clock = ManualClock(1_000.0)
    first, second = shared_models(2, 2, clock)
    first.set_inventory(Inventory({"listed": ListedRobot((), ())}))  # followed, never heard
    first.apply("r1", an_array(), "dds")
    assert not second.apply("r2", an_array(), "dds")
    first.set_inventory(Inventory({}))  # never heard, so forgotten at once
    assert second.apply("r2", an_array(), "dds")
    assert not second.apply("r3", an_array(), "dds")
    clock.now += 61  # r1 down long since
    assert first.retire("r1") == "retired"
    assert second.apply("r3", an_array(), "dds")


class Interleaved(list[int]):
    """Shared counts where another worker does something just before this one's first write."""

    def __init__(self, counts: list[int]) -> None:
        """Counts as given; `before_write` runs once, at the first write."""
        super().__init__(counts)
        self.before_write: Callable[[], object] | None = None
        self.writes = 0

    def __setitem__(self, index: int, value: int) -> None:  # type: ignore[override]
        """Let the other worker in first, then write."""
        self.writes += 1
        if self.before_write is not None:
            other, self.before_write = self.before_write, None
            other()
        super().__setitem__(index, value)


def test_two_workers_taking_the_last_place_at_once_do_not_both_take_it() -> None:
    counts = Interleaved([0, 0])
    first, second = (SharedRobotCap(2, counts, slot) for slot in range(2))
    counts[0] = 1  # the first worker holds a robot: one place left
    taken_by_second: list[bool] = []
    counts.before_write = lambda: taken_by_second.append(second.admit(0))
    # The first sees the place free, and the second takes it before the first counts its robot.
    assert not first.admit(1)
    assert taken_by_second == [True]
    assert list(counts) == [1, 1]


def test_a_robot_refused_at_the_cap_writes_nothing() -> None:
    counts = Interleaved([0, 0])
    full = SharedRobotCap(2, counts, 0)
    SharedRobotCap(2, counts, 1).holds(2)
    counts.writes = 0
    assert not full.admit(0)
    assert counts.writes == 0  # every message of a refused robot asks: no write, no cache line bounced


def take_robots(counts: SharedCounts, slot: int, start: Connection) -> None:
    """In a process of its own: try to take `RACED_ROBOTS` robots, at once with the other process."""
    cap = SharedRobotCap(RACED_CAP, counts.slots, slot)
    model = FleetModel(FleetLimits(max_robots=RACED_CAP), robot_cap=cap)
    start.send("ready")
    start.recv()  # both models built: go
    for index in range(RACED_ROBOTS):
        model.register(f"w{slot}-r{index}", "dds")


def test_two_processes_taking_robots_at_once_take_exactly_the_cap() -> None:
    counts = SharedCounts.create(2)
    pipes = [Pipe() for _ in range(2)]
    processes = [start_child(take_robots, (counts, slot, pipes[slot][1])) for slot in range(2)]  # as the pool
    try:
        for ours, theirs in pipes:
            theirs.close()
            assert ours.poll(30) and ours.recv() == "ready"
        for ours, _ in pipes:
            ours.send("go")
        for process in processes:
            process.join(60)
            assert process.exitcode == 0
    finally:
        for process in processes:
            if process.is_alive():
                process.kill()
    assert sum(counts.slots) == RACED_CAP  # each model alone would have taken its 5,000
