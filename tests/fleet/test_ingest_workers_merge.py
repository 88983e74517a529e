"""Ingest workers' answers joined: the same fleet split over k models serves exactly what one model serves.

Each test feeds the same arrays to one model and to k worker models (each given only the robots its
shard owns, as the DDS and Zenoh sources filter them), then compares what the exporter would serve.
The process machinery is tested end to end in test_ingest_workers.py.
"""

from __future__ import annotations

import pickle
import re
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from prometheus_client.parser import text_string_to_metric_families

from overseer.config import Config
from overseer.fleet.documents import ComponentQuery, components_document, robot_document, robots_document
from overseer.fleet.exposition import ExpositionPart, FleetExposition
from overseer.fleet.workers.merge import (
    CounterCarry,
    counters_part,
    merge_components_documents,
    merge_robots_documents,
    merge_snapshots,
    part_counters,
    portable_robots,
)
from overseer.fleet.workers.process import worker_config
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.model.shard import Shard
from overseer.serve.assembler import ExpositionAssembler
from overseer.serve.exposition_formats import OPENMETRICS, TEXT, ExpositionFormat
from support.clock import ManualClock
from support.examples import examples
from support.oracle import parse_openmetrics
from support.strategies import arrays

HOSTILE = ['quote"d', "back\\slash", "new\nline", "unicode ☃ 🤖", "brace}{=,", ""]
LIMITS = FleetLimits(stale_after=5, robot_timeout=10, expire_after=60, max_components_per_robot=6)


class SplitFleet:
    """One model holding the whole fleet, and `workers` models each holding the robots it owns."""

    def __init__(self, workers: int, shard: Shard | None = None) -> None:
        """Empty models on one clock."""
        self.clock = ManualClock()
        self.shard = shard or Shard()
        self.whole = FleetModel(LIMITS, self.clock)
        self.owners = [self.shard.for_worker(index, workers) for index in range(workers)]
        self.parts = [FleetModel(LIMITS, self.clock) for _ in range(workers)]

    def apply(self, robot: str, array: DiagnosticArray) -> None:
        """Feed `array` to the whole model and to the one worker model that owns `robot`."""
        if not self.shard.owns(robot):
            return
        self.whole.apply(robot, array, "dds")
        owners = [part for owner, part in zip(self.owners, self.parts, strict=True) if owner.owns(robot)]
        assert len(owners) == 1
        owners[0].apply(robot, array, "dds")

    def count(self, robot: str, result: str) -> None:
        """Count a message result in the whole model and in the owner's (as a source would)."""
        self.whole.count_message("dds", result)
        owner = next(part for o, part in zip(self.owners, self.parts, strict=True) if o.owns(robot))
        owner.count_message("dds", result)


def varied_fleet(workers: int, robots: int = 24) -> SplitFleet:
    fleet = SplitFleet(workers)
    for index in range(robots):
        name = f"robot{index}/{HOSTILE[index % len(HOSTILE)]}"
        statuses = [
            DiagnosticStatus(
                (index + number) % 4,
                f"/Part{number}",
                HOSTILE[number % len(HOSTILE)],
                f"hw{number}",
                (("v", f"{index}.{number} V"), ("t", "nan")),
            )
            for number in range(4 + index % 5)  # some beyond the component limit: dropped and counted
        ]
        statuses.append(DiagnosticStatus(7, "/bad level", "", "", ()))  # dropped: invalid level
        fleet.apply(name, DiagnosticArray(0, 0, "", tuple(statuses)))
        if index % 3 == 0:
            fleet.count(name, "decode_error")
    fleet.clock.now += 3
    for index in range(0, robots, 4):  # a quarter report again, one component short: the others go stale
        name = f"robot{index}/{HOSTILE[index % len(HOSTILE)]}"
        fleet.apply(name, DiagnosticArray(0, 0, "", (DiagnosticStatus(1, "/Part0", "again", "hw0", ()),)))
    fleet.clock.now += 3
    return fleet


def part(model: FleetModel) -> ExpositionPart:
    """A model's rendered part, as a worker sends it over its pipe."""
    rendered = FleetExposition(model, re.compile(".*")).render_part()
    return pickle.loads(pickle.dumps(rendered))  # type: ignore[no-any-return]


def exposition(
    parts: list[ExpositionPart], fmt: ExpositionFormat = TEXT, transports: tuple[str, ...] = ("dds",)
) -> bytes:
    """The exposition the exporter writes from `parts`."""
    return ExpositionAssembler(transports, external_url="http://x").assemble(parts, fmt)


def samples(
    text: bytes, fmt: ExpositionFormat = TEXT
) -> dict[str, list[tuple[str, tuple[tuple[str, str], ...], str]]]:
    """Each family's samples, sorted (values as text, so NaN equals NaN); fails on a family given twice.

    OpenMetrics is read by prometheus-client's strict parser, which also fails on a malformed answer.
    """
    families: dict[str, list[tuple[str, tuple[tuple[str, str], ...], str]]] = {}
    parse = parse_openmetrics if fmt.openmetrics else text_string_to_metric_families
    for family in parse(text.decode()):
        assert family.name not in families, f"{family.name} appears twice"
        families[family.name] = sorted(
            (sample.name, tuple(sorted(sample.labels.items())), repr(sample.value))
            for sample in family.samples
        )
    return families


@pytest.mark.parametrize("workers", [1, 2, 3, 5])
def test_every_robot_of_a_shard_is_owned_by_exactly_one_of_its_workers(workers: int) -> None:
    names = [f"robot{index}" for index in range(3000)] + HOSTILE
    for shard in (Shard(), Shard(1, 3)):
        for name in names:
            owners = [index for index in range(workers) if shard.for_worker(index, workers).owns(name)]
            assert len(owners) == (1 if shard.owns(name) else 0), name
            # The Zenoh relay asks which worker it is: the one that owns it, or none of another shard's.
            assert shard.worker_of(name, workers) == (owners[0] if owners else None), name
    spread = [
        sum(Shard().for_worker(index, workers).owns(name) for name in names) for index in range(workers)
    ]
    assert min(spread) > 0.8 * len(names) / workers  # the hash spreads robots evenly


def test_a_worker_outside_the_pool_is_refused() -> None:
    with pytest.raises(ValueError, match="worker 2 is not one of 0-1"):
        Shard().for_worker(2, 2)


@pytest.mark.parametrize("fmt", [TEXT, OPENMETRICS], ids=["text", "openmetrics"])
@pytest.mark.parametrize("workers", [2, 3])
def test_joined_exposition_has_exactly_the_series_of_one_model(workers: int, fmt: ExpositionFormat) -> None:
    fleet = varied_fleet(workers)
    transports = ("dds", "zenoh")
    whole = exposition([part(fleet.whole)], fmt, transports)
    parts = [part(model) for model in fleet.parts]
    assert sum(p.robots for p in parts) == len(fleet.whole.snapshot().robots)
    assert all(p.robots for p in parts)  # every worker has robots: the join is really tested
    joined = exposition(parts, fmt, transports)
    assert samples(joined, fmt) == samples(whole, fmt)
    # Counters add up: invalid levels and component-limit drops were counted in every worker.
    dropped = dict((labels, value) for _, labels, value in samples(joined, fmt)["overseer_statuses_dropped"])
    assert dropped[(("reason", "invalid_level"),)] == repr(24.0)  # one per robot, whichever worker counted it
    assert len(joined.splitlines()) == len(whole.splitlines())
    # The headers and the end are the format's, written once whatever the number of workers.
    assert joined.count(b"# TYPE ros_diagnostics_level gauge\n") == 1
    assert joined.endswith(b"# EOF\n") is fmt.openmetrics


@pytest.mark.parametrize(
    "query",
    [
        ComponentQuery(),
        ComponentQuery(limit=3),
        ComponentQuery(limit=1000),
        ComponentQuery(levels=None, text="part1"),
        ComponentQuery(text="quote"),
        ComponentQuery(robot="robot5/new\nline"),
        ComponentQuery(text="no such thing"),
    ],
)
def test_joined_components_document_equals_one_models(query: ComponentQuery) -> None:
    from overseer.levels import Level

    fleet = varied_fleet(3)
    for levels in (None, frozenset({Level.ERROR, Level.STALE})):
        asked = replace(query, levels=levels)
        whole = components_document(fleet.whole.snapshot(), asked)
        answers = [components_document(model.snapshot(), asked) for model in fleet.parts]
        joined = merge_components_documents(answers, asked.limit, whole["generated_at"])
        assert joined == whole


def test_joined_robots_document_and_each_robot_equal_one_models() -> None:
    fleet = varied_fleet(3)
    whole_snapshot = fleet.whole.snapshot()
    whole = robots_document(whole_snapshot)
    joined = merge_robots_documents(
        [robots_document(m.snapshot()) for m in fleet.parts], whole["generated_at"]
    )
    assert joined == whole
    for robot in whole_snapshot.robots:
        owner = next(part for o, part in zip(fleet.owners, fleet.parts, strict=True) if o.owns(robot.name))
        snapshot = owner.snapshot()
        found = snapshot.find(robot.name)
        assert found is not None
        assert robot_document(snapshot, found) == robot_document(whole_snapshot, robot)


def test_joined_snapshot_crosses_a_pipe_and_judges_as_one_model() -> None:
    fleet = varied_fleet(2)
    whole = fleet.whole.snapshot()
    sent = [
        pickle.loads(pickle.dumps(replace(s, robots=tuple(portable_robots(s)))))
        for s in (m.snapshot() for m in fleet.parts)
    ]
    joined = merge_snapshots(sent, LIMITS, whole.taken_at, whole.generated_at)
    assert sorted(r.name for r in joined.robots) == sorted(r.name for r in whole.robots)
    by_name = {robot.name: robot for robot in joined.robots}
    for robot in whole.robots:
        assert joined.robot_level(by_name[robot.name]) == whole.robot_level(robot)
        assert dict(by_name[robot.name].components) == dict(robot.components)
    assert dict(joined.message_counts) == dict(whole.message_counts)
    assert dict(joined.dropped_statuses) == dict(whole.dropped_statuses)


def test_every_worker_holds_the_fleets_robot_cap_not_a_share() -> None:
    # They count their robots together against it (model/robot_cap.py): a share would refuse robots
    # while the fleet is under the cap, wherever the hash put more than a share's worth in one worker.
    config = replace(Config(), fleet=FleetLimits(max_robots=7))
    assert [worker_config(config, index, 3).fleet.max_robots for index in range(3)] == [7, 7, 7]


@settings(max_examples=examples(40), deadline=None)
@given(
    st.lists(st.tuples(st.sampled_from([f"r{i}" for i in range(12)]), arrays(st.integers(0, 3))), max_size=30)
)
def test_any_arrays_split_over_workers_serve_what_one_model_serves(
    received: list[tuple[str, DiagnosticArray]],
) -> None:
    fleet = SplitFleet(3)
    for robot, array in received:
        fleet.apply(robot, array)
        fleet.clock.now += 1
    parts = [part(model) for model in fleet.parts]
    for fmt in (TEXT, OPENMETRICS):
        assert samples(exposition(parts, fmt), fmt) == samples(exposition([part(fleet.whole)], fmt), fmt)
    query = ComponentQuery(limit=5)
    joined = merge_components_documents(
        [components_document(m.snapshot(), query) for m in fleet.parts], 5, 0.0
    )
    assert joined | {"generated_at": 0.0} == components_document(fleet.whole.snapshot(), query) | {
        "generated_at": 0.0
    }


def test_carried_counters_never_go_back_when_a_worker_restarts_or_misses_a_scrape() -> None:
    carry = CounterCarry(2)
    assert carry.totals([(0, 0, {("m",): 10}), (1, 0, {("m",): 5})]) == {("m",): 15}
    assert carry.totals([(0, 0, {("m",): 12})]) == {("m",): 17}  # worker 1 missed it: its last 5 held
    # Worker 1 restarted (generation 1): its counters start from zero, its old 5 stay in the base.
    assert carry.totals([(0, 0, {("m",): 13}), (1, 1, {("m",): 2, ("e",): 1})]) == {("m",): 20, ("e",): 1}
    # Answers of two concurrent scrapes may be joined in the other order: the larger value holds.
    assert carry.totals([(0, 0, {("m",): 12}), (1, 1, {("m",): 3})]) == {("m",): 21, ("e",): 1}


def test_joined_exposition_counters_survive_a_restarted_worker() -> None:
    fleet = varied_fleet(2)
    parts = [part(model) for model in fleet.parts]
    carry = CounterCarry(2)
    before = counters_part(carry.totals((i, 0, part_counters(p)) for i, p in enumerate(parts)))
    restarted = part(FleetModel(LIMITS, fleet.clock))  # counts 0
    after = counters_part(carry.totals([(0, 0, part_counters(parts[0])), (1, 1, part_counters(restarted))]))
    assert after.message_counts == before.message_counts
    assert after.dropped_statuses == before.dropped_statuses
    assert sum(after.message_counts.values()) == sum(
        sum(part.message_counts.values()) for part in parts
    )  # nothing counted twice either


def test_openmetrics_counters_carried_replace_the_summed_ones() -> None:
    fleet = varied_fleet(2)
    parts = [part(model) for model in fleet.parts]
    carry = CounterCarry(2)
    totals = carry.totals((i, 0, part_counters(p)) for i, p in enumerate(parts))
    without = [
        replace(p, message_counts={}, dropped_statuses={}, truncated_strings=0, source_errors={})
        for p in parts
    ]
    joined = samples(exposition([*without, counters_part(totals)], OPENMETRICS), OPENMETRICS)
    whole = samples(exposition([part(fleet.whole)], OPENMETRICS), OPENMETRICS)
    assert joined == whole
    restarted = [
        (0, 0, part_counters(parts[0])),
        (1, 1, part_counters(part(FleetModel(LIMITS, fleet.clock)))),
    ]
    after = samples(
        exposition([without[0], counters_part(carry.totals(restarted))], OPENMETRICS), OPENMETRICS
    )
    assert after["overseer_messages"] == whole["overseer_messages"]
