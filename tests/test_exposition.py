"""The fast text exposition renders exactly what prometheus-client renders from the collector."""

from __future__ import annotations

import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from prometheus_client import generate_latest
from prometheus_client.registry import CollectorRegistry

from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.serve import exposition as exposition_module
from overseer.serve.exposition import FleetExposition
from overseer.serve.message_labels import DEFAULT_MESSAGE_LABELS, MESSAGE_LABEL_MODES, MessageLabels
from overseer.serve.metrics import FleetCollector


class Clock:
    """A hand-moved clock."""

    def __init__(self) -> None:
        """Start at a fixed unix time."""
        self.now = 1_700_000_000.0

    def __call__(self) -> float:
        """The current time."""
        return self.now


HOSTILE = ['quote"d', "back\\slash", "new\nline", "unicode ☃ 🤖", "brace}{=,", "tab\there", "", "\ufffd"]
# Status messages go into a label too: besides the hostile names, a lone surrogate (not encodable as
# UTF-8), a long message with a wide character at the cut, and a message full of escapes.
HOSTILE_MESSAGES = [*HOSTILE, "lone \ud800 surrogate", "x" * 98 + "🤖☃" + "y" * 50, '\\"\n' * 60]


def fleet() -> tuple[FleetModel, Clock]:
    clock = Clock()
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


def both(
    model: FleetModel,
    exposition: FleetExposition,
    value_keys: str = ".*",
    messages: MessageLabels = DEFAULT_MESSAGE_LABELS,
    external_url: str | None = None,
) -> tuple[bytes, bytes]:
    registry = CollectorRegistry()
    collector = FleetCollector(
        model, re.compile(value_keys), ["dds"], messages=messages, external_url=external_url
    )
    registry.register(collector)
    return exposition.render(), generate_latest(registry)


@pytest.mark.parametrize(
    ("value_keys", "messages", "external_url"),
    [
        (".*", MessageLabels(), None),
        ("v|big", MessageLabels(), None),
        (".*", MessageLabels("all", 20), 'https://ops.example/over"seer\\\n'),
        (".*", MessageLabels("none"), "http://127.0.0.1:9849"),
    ],
)
def test_fast_exposition_equals_collector_through_changes_staleness_and_expiry(
    value_keys: str, messages: MessageLabels, external_url: str | None
) -> None:
    model, clock = fleet()
    exposition = FleetExposition(
        model, re.compile(value_keys), ["dds"], messages=messages, external_url=external_url
    )

    def both_now() -> tuple[bytes, bytes]:
        return both(model, exposition, value_keys, messages, external_url)

    fast, reference = both_now()
    assert fast == reference
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
        fast, reference = both_now()
        assert fast == reference


def test_a_lost_publisher_renders_its_robot_down_and_a_returning_one_up() -> None:
    model, _ = fleet()
    exposition = FleetExposition(model, re.compile(".*"), ["dds"])
    robot = 'robot0/quote"d'
    label = b'ros_diagnostics_robot_up{robot="robot0/quote\\"d"} '
    assert label + b"1.0" in exposition.render()
    model.set_publisher_alive(robot, False)
    fast, reference = both(model, exposition)
    assert fast == reference and label + b"0.0" in fast
    assert b'ros_diagnostics_level{component="/Motor",hardware_id="m1",robot="robot0/quote\\"d"} 3.0' in fast
    model.set_publisher_alive(robot, True)
    fast, reference = both(model, exposition)
    assert fast == reference and label + b"1.0" in fast


def test_cached_lines_are_reused_for_unchanged_robots() -> None:
    model, _ = fleet()
    exposition = FleetExposition(model, re.compile(".*"), ["dds"])
    exposition.render()
    cached = dict(exposition._robots)
    model.touch('robot0/quote"d', "dds")
    exposition.render()
    assert all(exposition._robots[name] is lines for name, lines in cached.items())


def test_a_changed_component_is_rendered_again_and_the_others_are_copied(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    model, _ = fleet()
    exposition = FleetExposition(model, re.compile(".*"), ["dds"])
    robot = "robot9"
    three = tuple(DiagnosticStatus(0, f"/c{i}", "ok", "", (("v", str(i)),)) for i in range(3))
    model.apply(robot, DiagnosticArray(0, 0, "", three), "dds")
    exposition.render()
    rendered: list[bytes] = []
    original_add = exposition_module._LinesBuilder.add

    def counting_add(self: exposition_module._LinesBuilder, index: int, *family_lines: bytes) -> None:
        rendered.append(family_lines[0])
        original_add(self, index, *family_lines)

    monkeypatch.setattr(exposition_module._LinesBuilder, "add", counting_add)
    changed = (three[0], three[1]._replace(values=(("v", "7"),)), three[2])
    model.apply(robot, DiagnosticArray(0, 0, "", changed), "dds")
    fast, reference = both(model, exposition)
    assert fast == reference
    assert len(rendered) == 1 and b'component="/c1"' in rendered[0]


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
    st.tuples(st.just("alive"), _robots, st.booleans()),
)


@settings(max_examples=300, deadline=None)
@given(
    steps=st.lists(_steps, min_size=1, max_size=12),
    messages=st.builds(
        MessageLabels, mode=st.sampled_from(MESSAGE_LABEL_MODES), length=st.sampled_from([1, 2, 5, 100])
    ),
    external_url=st.sampled_from([None, "http://127.0.0.1:9849", 'https://x/"\\\n']),
)
def test_cached_exposition_equals_collector_through_any_changes(
    steps: list[tuple[object, ...]], messages: MessageLabels, external_url: str | None
) -> None:
    clock = Clock()
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=10, expire_after=60), clock=clock)
    exposition = FleetExposition(
        model, re.compile(".*"), ["dds"], messages=messages, external_url=external_url
    )
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
            case ("alive", str(robot), bool(alive)):
                model.set_publisher_alive(robot, alive)
        fast, reference = both(model, exposition, messages=messages, external_url=external_url)
        assert fast == reference


def test_fast_exposition_with_the_icinga2_push_metrics_equals_the_registry_with_both_collectors() -> None:
    from overseer.push.icinga2_metrics import PushCollector, PushStats

    model, _ = fleet()
    stats = PushStats()
    stats.delivered(7, 1_700_000_000.5)
    stats.failed("http_401")
    stats.failed("connection")
    stats.set_pending(3)
    collector = PushCollector(stats)
    registry = CollectorRegistry()
    registry.register(FleetCollector(model, re.compile(".*"), ["dds"]))
    registry.register(collector)
    fast = FleetExposition(model, re.compile(".*"), ["dds"], [collector]).render()
    assert fast == generate_latest(registry)
    assert b'overseer_icinga2_pushes_total{result="http_401"} 1.0\n' in fast
    assert b"overseer_icinga2_pending_results 3.0\n" in fast
