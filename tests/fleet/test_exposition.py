"""The cached exposition renders exactly what prometheus-client renders from the oracle, in both formats."""

from __future__ import annotations

import gc
import sys
from collections.abc import Callable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from overseer.config.metrics import MESSAGE_LABEL_MODES, NO_VALUE_KEYS, metrics_config
from overseer.fleet import exposition as exposition_module
from overseer.fleet.deflated import Deflated, inflate
from overseer.fleet.message_labels import MessageLabels
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.serve.exposition_formats import OPENMETRICS, TEXT
from support.clock import ManualClock
from support.examples import examples
from support.rendering import FORMATS, Rendering, gunzip_one_member

HOSTILE = ['quote"d', "back\\slash", "new\nline", "unicode ☃ 🤖", "brace}{=,", "tab\there", "", "\ufffd"]
# Status messages go into a label too: besides the hostile names, a lone surrogate (not encodable as
# UTF-8), a long message with a wide character at the cut, and a message full of escapes.
HOSTILE_MESSAGES = [*HOSTILE, "lone \ud800 surrogate", "x" * 98 + "🤖☃" + "y" * 50, '\\"\n' * 60]


def fleet() -> tuple[FleetModel, ManualClock]:
    clock = ManualClock()
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=10, expire_after=60), clock=clock)
    for index, name in enumerate(HOSTILE):
        statuses = (
            DiagnosticStatus(
                index % 4, name or "/empty", name, name, ((name, "1.5"), ("v", "12 V"), ("v", "3"))
            ),
            DiagnosticStatus(
                1,
                "/Motor",
                "warm",
                "m1",
                (("nan", "nan"), ("inf", "-inf"), ("big", "1e300"), ("z", "0"), ("nz", "-0")),
            ),
            *(
                DiagnosticStatus(1 + index % 3, f"/Message/{number}", message, "", ())
                for number, message in enumerate(HOSTILE_MESSAGES)
            ),
        )
        model.apply(f"robot{index}/{name}", DiagnosticArray(0, 0, "", statuses), "dds")
    model.count_message("ros1", "decode_error")
    model.count_source_error("ros1", "master_unreachable")
    model.count_source_error("ros1", 'odd "reason"')
    return model, clock


def assert_equal_in_both_formats(rendering: Rendering) -> bytes:
    """Production's text and OpenMetrics equal the oracle's; returns the text."""
    for fmt in FORMATS:
        fast, reference = rendering.both(fmt)
        assert fast == reference, fmt
    return rendering.fast(TEXT)


@pytest.mark.parametrize(
    ("value_keys", "messages", "external_url", "level_changes"),
    [
        (".*", MessageLabels(), None, True),
        ("v|big", MessageLabels(), None, True),
        (".*", MessageLabels("all", 20), 'https://ops.example/over"seer\\\n', True),
        (".*", MessageLabels("none"), "http://127.0.0.1:9849", True),
        ("(?!)", MessageLabels(), None, False),  # the cheapest: no values, no level changes
    ],
)
def test_fast_exposition_equals_the_oracle_in_both_formats_through_changes_staleness_and_expiry(
    value_keys: str, messages: MessageLabels, external_url: str | None, level_changes: bool
) -> None:
    model, clock = fleet()
    rendering = Rendering(
        model, value_keys, messages=messages, external_url=external_url, level_changes=level_changes
    )
    fast = assert_equal_in_both_formats(rendering)
    assert (b"ros_diagnostics_level_changes_total{" in fast) is level_changes
    assert (b"ros_diagnostics_value{" in fast) is (value_keys != "(?!)")
    # 8 robots of 13 components; the first component of robots 0 and 4 is the only one at OK.
    assert (
        fast.count(b"ros_diagnostics_status_message{")
        == {"none": 0, "problems": 102, "all": 104}[messages.mode]
    )
    steps = [
        lambda: model.apply(
            "robot1/back\\slash", DiagnosticArray(0, 0, "", (DiagnosticStatus(2, "/new", "", "", ()),)), "dds"
        ),
        lambda: model.touch("robot2/new\nline", "dds"),
        lambda: setattr(clock, "now", clock.now + 6),  # most components stale
        lambda: model.touch("robot3/unicode ☃ 🤖", "dds"),
        lambda: setattr(clock, "now", clock.now + 5),  # robots down
        lambda: model.touch("robot3/unicode ☃ 🤖", "dds"),
        lambda: setattr(clock, "now", clock.now + 60),
        model.expire,
    ]
    for step in steps:
        step()
        assert_equal_in_both_formats(rendering)


def test_a_lost_publisher_renders_its_robot_down_and_a_returning_one_up() -> None:
    model, clock = fleet()
    rendering = Rendering(model)
    robot = 'robot0/quote"d'
    label = b'ros_diagnostics_robot_up{robot="robot0/quote\\"d"} '
    assert label + b"1.0" in rendering.fast()
    model.publisher_left(robot)
    fast = assert_equal_in_both_formats(rendering)
    assert label + b"0.0" in fast
    assert b'ros_diagnostics_level{component="/Motor",hardware_id="m1",robot="robot0/quote\\"d"} 3.0' in fast
    clock.now += 1
    assert model.touch(robot, "dds")  # its next message
    assert label + b"1.0" in assert_equal_in_both_formats(rendering)


def test_cached_lines_are_reused_for_unchanged_robots() -> None:
    model, _ = fleet()
    rendering = Rendering(model)
    rendering.fast(TEXT)
    cached = dict(rendering.exposition._robots)
    model.touch('robot0/quote"d', "dds")
    rendering.fast(OPENMETRICS)  # the same cached lines serve either format
    assert all(rendering.exposition._robots[name] is lines for name, lines in cached.items())


def test_robots_that_held_still_for_a_render_are_sent_as_runs_recompressed_whole() -> None:
    model, _ = fleet()
    for index in range(40):
        statuses = tuple(DiagnosticStatus(index % 3, f"/c{c}", "fine", "", (("v", "1"),)) for c in range(20))
        model.apply(f"still{index}", DiagnosticArray(0, 0, "", statuses), "dds")
    rendering = Rendering(model)
    first = rendering.assembler.assemble_gzip([rendering.exposition.render_part()], TEXT)
    assert_equal_in_both_formats(rendering)  # renders again: every run held still since the first
    recompressed = [runs.recompressed for runs in rendering.exposition._runs]
    assert all(recompressed)
    model.touch("still3", "dds")  # a robot that republished the same array changes no run
    joined = rendering.assembler.assemble_gzip([rendering.exposition.render_part()], TEXT)
    assert [runs.recompressed for runs in rendering.exposition._runs] == recompressed
    assert gunzip_one_member(joined) == rendering.oracle(TEXT)
    assert len(joined) < 0.8 * len(first)


def three_components_rendered(
    level: int, value_keys: str = ".*"
) -> tuple[Rendering, Callable[[], None], Callable[[], None]]:
    """Robot9 of three components at `level`, rendered once; what changes its second's value; its level."""
    model, _ = fleet()
    rendering = Rendering(model, value_keys)
    three = tuple(DiagnosticStatus(level, f"/c{i}", "warm", "", (("v", str(i)),)) for i in range(3))
    model.apply("robot9", DiagnosticArray(0, 0, "", three), "dds")
    rendering.fast()

    def change_a_value() -> None:
        changed = (three[0], three[1]._replace(values=(("v", "7"),)), three[2])
        model.apply("robot9", DiagnosticArray(0, 0, "", changed), "dds")

    def change_a_level() -> None:
        changed = (three[0], three[1]._replace(level=2, values=(("v", "7"),)), three[2])
        model.apply("robot9", DiagnosticArray(0, 0, "", changed), "dds")

    return rendering, change_a_value, change_a_level


def record_rendering(monkeypatch: pytest.MonkeyPatch) -> tuple[list[tuple[str, int]], list[int]]:
    """The (family, component index) of every line rendered from now on, and the sizes of pieces inflated."""
    rendered: list[tuple[str, int]] = []
    inflated: list[int] = []
    for family in ("level", "changes", "values", "message"):
        original = getattr(exposition_module._ComponentLines, family)

        def recording(
            self: exposition_module._ComponentLines,
            index: int,
            family: str = family,
            original: Callable[[exposition_module._ComponentLines, int], bytes] = original,
        ) -> bytes:
            rendered.append((family, index))
            return original(self, index)

        monkeypatch.setattr(exposition_module._ComponentLines, family, recording)

    def recording_inflate(piece: Deflated) -> bytes:
        inflated.append(piece.size)
        return inflate(piece)

    monkeypatch.setattr(exposition_module, "inflate", recording_inflate)
    return rendered, inflated


def test_a_changed_value_renders_only_its_components_values_and_copies_the_rest(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rendering, change_a_value, _ = three_components_rendered(1)  # WARN: a status-message line each
    before = rendering.exposition._robots["robot9"]
    rendered, inflated = record_rendering(monkeypatch)
    change_a_value()
    fast, reference = rendering.both(TEXT)
    assert fast == reference
    # Its level, level changes and message are as they were: those families are neither rendered
    # nor inflated, and keep their compressed piece.
    assert rendered == [("values", 1)]
    after = rendering.exposition._robots["robot9"]
    assert inflated == [before.values.size]
    assert after.levels is before.levels and after.changes is before.changes
    assert after.messages is before.messages and after.values != before.values
    assert rendering.fast(OPENMETRICS) == rendering.oracle(OPENMETRICS) and rendered == [("values", 1)]


@pytest.mark.parametrize("value_keys", [[], [NO_VALUE_KEYS]], ids=["file: []", "command line: '(?!)'"])
def test_with_no_value_exported_a_changed_value_renders_and_inflates_nothing(
    monkeypatch: pytest.MonkeyPatch, value_keys: list[str]
) -> None:
    # The setting a large fleet is advised, in the configuration file or on the command line (where a
    # repeated option cannot be given no value): its values change all the time.
    pattern = metrics_config({"value_keys": value_keys}).value_key_pattern.pattern
    rendering, change_a_value, change_a_level = three_components_rendered(1, pattern)
    before = rendering.exposition._robots["robot9"]
    rendered, inflated = record_rendering(monkeypatch)
    change_a_value()
    fast, reference = rendering.both(TEXT)
    assert fast == reference
    after = rendering.exposition._robots["robot9"]
    assert rendered == [] and inflated == []
    assert after is not before and after.signature != before.signature  # the new revision's
    assert [after.levels, after.changes, after.values, after.messages] == [
        before.levels,
        before.changes,
        before.values,
        before.messages,
    ]
    assert after.levels is before.levels and after.messages is before.messages
    change_a_level()  # a level still renders, its values none
    fast, reference = rendering.both(TEXT)
    assert fast == reference
    assert sorted(rendered) == [("changes", 1), ("level", 1), ("message", 1), ("values", 1)]
    assert b'ros_diagnostics_level{component="/c1",hardware_id="",robot="robot9"} 2.0' in fast


def test_a_changed_level_renders_its_components_level_changes_and_message_lines(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rendering, _, change_a_level = three_components_rendered(1)
    rendered, _ = record_rendering(monkeypatch)
    change_a_level()
    fast, reference = rendering.both(TEXT)
    assert fast == reference
    assert sorted(rendered) == [("changes", 1), ("level", 1), ("message", 1), ("values", 1)]


def test_a_level_that_went_and_came_back_between_renders_renders_its_two_changes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Its level, message and values are as they were; only its count of level changes is not.
    rendering, _, change_a_level = three_components_rendered(1)
    model = rendering.exposition._model
    three = tuple(DiagnosticStatus(1, f"/c{i}", "warm", "", (("v", str(i)),)) for i in range(3))
    rendered, _ = record_rendering(monkeypatch)
    change_a_level()
    model.apply("robot9", DiagnosticArray(0, 0, "", three), "dds")
    fast, reference = rendering.both(TEXT)
    assert fast == reference
    assert b'ros_diagnostics_level_changes_total{component="/c1",hardware_id="",robot="robot9"} 2.0' in fast
    assert ("changes", 1) in rendered
    assert {index for _, index in rendered} == {1}  # the others copied: the partial path ran


def test_a_record_replaced_after_a_render_is_kept_alive_by_nothing_but_its_reader() -> None:
    # Between two scrapes a minute apart a fleet replaces nearly half its records: were the cache to
    # hold the ones it rendered, each would outlive its replacement until the next scrape.
    rendering, change_a_value, _ = three_components_rendered(1)
    snapshot = rendering.exposition._model.snapshot()
    record = next(robot for robot in snapshot.robots if robot.name == "robot9").components[("/c1", "")]
    del snapshot
    gc.collect()
    change_a_value()
    alone = tuple(record)  # a tuple no one else holds, counted the same way on any interpreter
    assert sys.getrefcount(record) == sys.getrefcount(alone)


def test_a_family_whose_lines_come_out_the_same_keeps_its_compressed_piece() -> None:
    model, _ = fleet()
    rendering = Rendering(model, value_keys="v")
    statuses = (DiagnosticStatus(1, "/c0", "warm", "", (("v", "1"), ("raw", "5"))),)
    model.apply("robot9", DiagnosticArray(0, 0, "", statuses), "dds")
    rendering.fast()
    before = rendering.exposition._robots["robot9"]
    # A value that is not exported changed: its values are rendered again, and come out the same bytes.
    model.apply(
        "robot9", DiagnosticArray(0, 0, "", (statuses[0]._replace(values=(("v", "1"), ("raw", "6"))),)), "dds"
    )
    fast, reference = rendering.both(TEXT)
    assert fast == reference
    after = rendering.exposition._robots["robot9"]
    assert after is not before and after.values is before.values


# Property: through any sequence of model changes, the cached exposition equals the collector's.
_statuses = st.lists(
    st.builds(
        DiagnosticStatus,
        level=st.integers(0, 3),
        name=st.sampled_from(["/a", "/b", "/c", 'q"uote', "/\u2603"]),
        message=st.sampled_from(["", "ok", "hot", *HOSTILE_MESSAGES]),
        hardware_id=st.sampled_from(["", "hw"]),
        values=st.lists(
            st.tuples(st.sampled_from(["v", "t"]), st.sampled_from(["1", "2.5", "x", "nan"])), max_size=2
        ).map(tuple),
    ),
    max_size=5,
).map(tuple)
_robots = st.sampled_from(["r0", "r1", "r2\n"])
_steps = st.one_of(
    st.tuples(st.just("apply"), _robots, _statuses),
    st.tuples(st.just("touch"), _robots),
    st.tuples(st.just("advance"), st.sampled_from([1.0, 3.0, 6.0, 11.0, 61.0])),
    st.tuples(st.just("expire")),
    st.tuples(st.just("forget"), _robots),
    st.tuples(st.just("left"), _robots),
)


@settings(max_examples=examples(300), deadline=None)
@given(
    steps=st.lists(_steps, min_size=1, max_size=12),
    messages=st.builds(
        MessageLabels, mode=st.sampled_from(MESSAGE_LABEL_MODES), length=st.sampled_from([1, 2, 5, 100])
    ),
    external_url=st.sampled_from([None, "http://127.0.0.1:9849", 'https://x/"\\\n']),
)
def test_cached_exposition_equals_the_oracle_in_both_formats_through_any_changes(
    steps: list[tuple[object, ...]], messages: MessageLabels, external_url: str | None
) -> None:
    clock = ManualClock()
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=10, expire_after=60), clock=clock)
    rendering = Rendering(model, messages=messages, external_url=external_url)
    for step in steps:
        match step:
            case ("apply", str(robot), tuple(statuses)):
                model.apply(robot, DiagnosticArray(0, 0, "", statuses), "dds", "t")
            case ("touch", str(robot)):
                model.touch(robot, "dds")
            case ("advance", float(seconds)):
                clock.now += seconds
            case ("expire",):
                model.expire()
            case ("forget", str(robot)):
                model.forget_topic(robot, "t")
            case ("left", str(robot)):
                model.publisher_left(robot)
        assert_equal_in_both_formats(rendering)


def test_fast_exposition_with_the_icinga2_push_metrics_equals_the_registry_with_both_collectors() -> None:
    from overseer.push.icinga2_metrics import PushCollector, PushStats

    model, _ = fleet()
    stats = PushStats()
    stats.delivered(7, 1_700_000_000.5)
    stats.failed("http_401")
    stats.failed("connection")
    stats.set_pending(3)
    fast = assert_equal_in_both_formats(Rendering(model, extra_collectors=[PushCollector(stats)]))
    assert b'overseer_icinga2_pushes_total{result="http_401"} 1.0\n' in fast
    assert b"overseer_icinga2_pending_results 3.0\n" in fast
