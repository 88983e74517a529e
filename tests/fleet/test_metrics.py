"""The /metrics view as production renders it: the metric contract, golden files, label escaping, promtool."""

from __future__ import annotations

import subprocess

import pytest
from prometheus_client.parser import text_string_to_metric_families

from overseer.codec import compiled
from overseer.fleet.message_labels import DEFAULT_MESSAGE_LABELS, MessageLabels, message_label_value
from overseer.fleet.metric_values import message_counts, numeric_value
from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import Expectation, FleetLimits, FleetModel, Inventory, ListedRobot
from overseer.serve.exposition_formats import OPENMETRICS
from support.clock import ManualClock
from support.oracle import parse_openmetrics
from support.paths import GOLDEN
from support.rendering import Rendering

GOLDEN_TEXT = GOLDEN / "metrics.txt"
GOLDEN_OPENMETRICS = GOLDEN / "metrics.openmetrics.txt"
CONTRACT = {
    "ros_diagnostics_level": "gauge",
    "ros_diagnostics_robot_level": "gauge",
    "ros_diagnostics_robot_up": "gauge",
    "ros_diagnostics_robot_last_message_timestamp_seconds": "gauge",
    "ros_diagnostics_level_changes": "counter",
    "ros_diagnostics_value": "gauge",
    "ros_diagnostics_status_message": "gauge",
    "overseer_messages": "counter",
    "overseer_build_info": "gauge",
}


def fleet_rendering(
    statuses: dict[str, list[DiagnosticStatus]],
    value_keys: str = ".*",
    messages: MessageLabels = DEFAULT_MESSAGE_LABELS,
    external_url: str | None = None,
) -> tuple[Rendering, FleetModel, ManualClock]:
    clock = ManualClock()
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=10, expire_after=60), clock=clock)
    for second in range(2):  # twice, a second apart: every robot's period is known
        clock.now += second
        for robot, items in statuses.items():
            model.apply(robot, DiagnosticArray(0, 0, "", tuple(items)), "dds")
    return Rendering(model, value_keys, messages=messages, external_url=external_url), model, clock


def sample_value(rendering: Rendering, name: str, labels: dict[str, str]) -> float | None:
    """The value of one sample of production's exposition, or None when it has none."""
    for family in text_string_to_metric_families(rendering.fast().decode()):
        for sample in family.samples:
            if sample.name == name and sample.labels == labels:
                return float(sample.value)
    return None


PAPER_FLEET = {
    "robot1": [
        DiagnosticStatus(
            0, "/Power/Robot Battery", "Charge OK", "power1", (("voltage", "12.6 V"), ("note", "fine"))
        ),
        DiagnosticStatus(1, "/Temp/Sensor1", "High temperature", "temp1", (("temperature", "71.0"),)),
    ],
    "site_a/robot7": [DiagnosticStatus(2, "/Camera/Cam1", "No frames received", "camera1", (("fps", "0"),))],
}


# robot7 is listed with labels and a component it does not report; robot9 is listed and never heard.
INVENTORY = Inventory(
    {
        "site_a/robot7": ListedRobot(
            (("model", "tb4"), ("site", 'site "a"')), (Expectation("/Power/Battery", exact="/Power/Battery"),)
        ),
        "site_a/robot9": ListedRobot((("site", "site_a"),)),
    }
)


@pytest.mark.parametrize("openmetrics", [False, True], ids=["text", "openmetrics"])
def test_exposition_matches_golden_file(openmetrics: bool) -> None:
    rendering, model, clock = fleet_rendering(PAPER_FLEET)
    model.set_inventory(INVENTORY)
    clock.now += 6
    model.apply("robot1", DiagnosticArray(0, 0, "", (PAPER_FLEET["robot1"][0],)), "dds")
    model.count_message("dds", "decode_error")
    text = (rendering.fast(OPENMETRICS) if openmetrics else rendering.fast()).decode()
    text = text.replace('version="' + _version() + '"', 'version="VERSION"')
    text = text.replace('codec="' + compiled.implementation() + '"', 'codec="CODEC"')
    assert text == (GOLDEN_OPENMETRICS if openmetrics else GOLDEN_TEXT).read_text(encoding="utf-8")


def _version() -> str:
    from overseer import __version__

    return __version__


def test_contract_names_and_types_are_exported() -> None:
    rendering, _, _ = fleet_rendering(PAPER_FLEET)
    families = {f.name: f.type for f in text_string_to_metric_families(rendering.fast().decode())}
    openmetrics = {f.name: f.type for f in parse_openmetrics(rendering.fast(OPENMETRICS).decode())}
    for name, kind in CONTRACT.items():
        assert families.get(name) == kind, name
        assert openmetrics.get(name) == kind, name


def test_levels_up_and_robot_level_samples() -> None:
    rendering, _, _ = fleet_rendering(PAPER_FLEET)
    battery = {"robot": "robot1", "component": "/Power/Robot Battery", "hardware_id": "power1"}
    assert sample_value(rendering, "ros_diagnostics_level", battery) == 0
    assert sample_value(rendering, "ros_diagnostics_robot_level", {"robot": "robot1"}) == 1
    assert sample_value(rendering, "ros_diagnostics_robot_level", {"robot": "site_a/robot7"}) == 2
    assert sample_value(rendering, "ros_diagnostics_robot_up", {"robot": "robot1"}) == 1
    assert sample_value(rendering, "ros_diagnostics_value", {**battery, "key": "voltage"}) == 12.6
    assert sample_value(rendering, "ros_diagnostics_value", {**battery, "key": "note"}) is None


def component_counts(rendering: Rendering, robot: str) -> dict[str, float | None]:
    """The robot's ros_diagnostics_robot_components samples, by level name."""
    return {
        level.name: sample_value(
            rendering, "ros_diagnostics_robot_components", {"robot": robot, "level": level.name}
        )
        for level in Level
    }


def test_each_robot_counts_its_components_at_every_level_now_stale_ones_and_a_down_robot_included() -> None:
    rendering, model, clock = fleet_rendering(PAPER_FLEET)
    assert component_counts(rendering, "robot1") == {"OK": 1, "WARN": 1, "ERROR": 0, "STALE": 0}
    assert component_counts(rendering, "site_a/robot7") == {"OK": 0, "WARN": 0, "ERROR": 1, "STALE": 0}
    clock.now += 6  # past stale_after: robot1's temperature is STALE, its battery reported again
    model.apply("robot1", DiagnosticArray(0, 0, "", (PAPER_FLEET["robot1"][0],)), "dds")
    assert component_counts(rendering, "robot1") == {"OK": 1, "WARN": 0, "ERROR": 0, "STALE": 1}
    clock.now += 10  # past robot_timeout: robot1 is down, every component STALE
    assert component_counts(rendering, "robot1") == {"OK": 0, "WARN": 0, "ERROR": 0, "STALE": 2}


def test_a_robots_level_changes_add_up_its_components_and_do_not_fall_when_one_is_forgotten() -> None:
    rendering, model, clock = fleet_rendering(PAPER_FLEET)
    battery, temperature = PAPER_FLEET["robot1"]
    robot1 = {"robot": "robot1"}
    for level in (0, 1, 2):  # WARN -> OK -> WARN -> ERROR: three changes
        model.apply("robot1", DiagnosticArray(0, 0, "", (battery, temperature._replace(level=level))), "dds")
    assert sample_value(rendering, "ros_diagnostics_robot_level_changes_total", robot1) == 3
    for _ in range(7):  # the battery alone for longer than expire_after (60 s): the temperature goes
        clock.now += 10
        model.apply("robot1", DiagnosticArray(0, 0, "", (battery,)), "dds")
    model.expire()
    labels = {"robot": "robot1", "component": temperature.name, "hardware_id": temperature.hardware_id}
    assert sample_value(rendering, "ros_diagnostics_level", labels) is None
    assert sample_value(rendering, "ros_diagnostics_robot_level_changes_total", robot1) == 3
    model.apply("robot1", DiagnosticArray(0, 0, "", (battery._replace(level=1),)), "dds")
    assert sample_value(rendering, "ros_diagnostics_robot_level_changes_total", robot1) == 4


def test_a_robots_level_changes_keep_those_of_a_topic_it_left_and_of_a_name_split_by_hardware_id() -> None:
    rendering, model, _ = fleet_rendering({})
    robot1 = {"robot": "robot1"}
    motor = DiagnosticStatus(0, "/Motor", "ok", "")
    for level in (0, 1, 0):  # two changes on /diagnostics
        model.apply(
            "robot1", DiagnosticArray(0, 0, "", (motor._replace(level=level),)), "dds", "/diagnostics"
        )
    model.forget_topic("robot1", "/diagnostics")  # it publishes /diagnostics_agg after all
    assert (
        sample_value(rendering, "ros_diagnostics_level", {**robot1, "component": "/Motor", "hardware_id": ""})
        is None
    )
    assert sample_value(rendering, "ros_diagnostics_robot_level_changes_total", robot1) == 2
    for level in (0, 2):  # one change on /diagnostics_agg
        model.apply(
            "robot1", DiagnosticArray(0, 0, "", (motor._replace(level=level),)), "dds", "/diagnostics_agg"
        )
    assert sample_value(rendering, "ros_diagnostics_robot_level_changes_total", robot1) == 3
    # Two statuses of that name with their own hardware_ids: they are kept apart, the one under the name goes.
    twins = (motor._replace(hardware_id="left"), motor._replace(hardware_id="right"))
    model.apply("robot1", DiagnosticArray(0, 0, "", twins), "dds", "/diagnostics_agg")
    assert sample_value(rendering, "ros_diagnostics_robot_level_changes_total", robot1) == 3


def test_a_robot_forgotten_and_listed_again_is_rendered_anew_not_from_its_former_lines() -> None:
    rendering, model, clock = fleet_rendering(PAPER_FLEET)
    laser, camera = Expectation("/Laser", exact="/Laser"), Expectation("/Camera", exact="/Camera")
    model.set_inventory(Inventory({"robotX": ListedRobot((("site", "a"),), (laser,))}))
    assert sample_value(rendering, "ros_diagnostics_robot_info", {"robot": "robotX", "site": "a"}) == 1
    model.set_inventory(Inventory({}))  # never heard: forgotten at once
    clock.now += 1
    model.set_inventory(Inventory({"robotX": ListedRobot((("site", "b"),), (laser, camera))}))
    assert sample_value(rendering, "ros_diagnostics_robot_info", {"robot": "robotX", "site": "a"}) is None
    assert sample_value(rendering, "ros_diagnostics_robot_info", {"robot": "robotX", "site": "b"}) == 1
    assert component_counts(rendering, "robotX") == {"OK": 0, "WARN": 0, "ERROR": 0, "STALE": 2}


def test_only_allowed_value_keys_are_exported() -> None:
    rendering, _, _ = fleet_rendering(PAPER_FLEET, value_keys="temperature|fps")
    text = rendering.fast().decode()
    assert 'key="temperature"' in text and 'key="fps"' in text
    assert 'key="voltage"' not in text


def test_forgotten_robot_disappears_from_exposition() -> None:
    rendering, model, clock = fleet_rendering(PAPER_FLEET)
    clock.now += 61
    model.apply("robot1", DiagnosticArray(0, 0, "", tuple(PAPER_FLEET["robot1"])), "dds")
    model.expire()
    text = rendering.fast().decode()
    assert "site_a/robot7" not in text
    assert 'robot="robot1"' in text


def test_a_start_up_status_and_a_new_hardware_id_move_the_series_at_once_never_left_stale() -> None:
    starting = DiagnosticStatus(0, "drive: Motor", "Node starting up", "", ())
    rendering, model, clock = fleet_rendering({"robot1": [starting]})
    assert (
        'ros_diagnostics_level{component="drive: Motor",hardware_id="",robot="robot1"} 0.0'
        in rendering.fast().decode()
    )
    for hardware_id in ("m1", "", "m2"):  # the real status, a broadcast without one, a swapped motor
        clock.now += 1
        model.apply("robot1", DiagnosticArray(0, 0, "", (starting._replace(hardware_id=hardware_id),)), "dds")
        fast, oracle = rendering.both()
        assert fast == oracle
        text = fast.decode()
        kept = hardware_id or "m1"
        assert [line for line in text.splitlines() if line.startswith("ros_diagnostics_level{")] == [
            f'ros_diagnostics_level{{component="drive: Motor",hardware_id="{kept}",robot="robot1"}} 0.0'
        ]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("12.5", 12.5),
        ("12.5 V", 12.5),
        ("-3e2", -300.0),
        ("True", 1.0),
        ("nan", None),
        ("OK", None),
        ("", None),
    ],
)
def test_numeric_values_are_read_from_text(text: str, expected: float | None) -> None:
    value = numeric_value(text)
    if text == "nan":
        assert value is not None and value != value
    else:
        assert value == expected


HOSTILE = [
    'quote"d',
    "back\\slash",
    "new\nline",
    "unicode ☃ 🤖 ロボット",
    "brace}{=,",
    "\ufffd invalid utf-8 replaced",
    "",
]


def hostile_rendering() -> Rendering:
    statuses = {
        f"robot{i}/{name}": [
            DiagnosticStatus(
                i % 4, name, name, name, ((name, "1.5"), ("nan", "nan"), ("inf", "inf"), ("neg", "-inf"))
            )
        ]
        for i, name in enumerate(HOSTILE)
    }
    rendering, _, _ = fleet_rendering(statuses)
    return rendering


def test_hostile_names_are_escaped_and_parse_back() -> None:
    text = hostile_rendering().fast().decode()
    families = {f.name: f for f in text_string_to_metric_families(text)}
    components = {s.labels["component"] for s in families["ros_diagnostics_level"].samples}
    assert components == set(HOSTILE)


def test_hostile_exposition_passes_promtool() -> None:
    text = hostile_rendering().fast()
    result = subprocess.run(["promtool", "check", "metrics"], input=text, capture_output=True, timeout=60)
    assert result.returncode == 0, result.stdout.decode() + result.stderr.decode()


def test_golden_exposition_passes_promtool() -> None:
    result = subprocess.run(
        ["promtool", "check", "metrics"], input=GOLDEN_TEXT.read_bytes(), capture_output=True, timeout=60
    )
    assert result.returncode == 0, result.stdout.decode() + result.stderr.decode()


def status_messages(rendering: Rendering) -> dict[tuple[str, str], str]:
    """(robot, component) → message label of every ros_diagnostics_status_message sample (value 1)."""
    found = {}
    for family in text_string_to_metric_families(rendering.fast().decode()):
        for sample in family.samples:
            if sample.name == "ros_diagnostics_status_message":
                assert sample.value == 1
                found[(sample.labels["robot"], sample.labels["component"])] = sample.labels["message"]
    return found


def test_status_messages_are_labels_of_the_components_not_ok_by_default() -> None:
    rendering, _, _ = fleet_rendering(PAPER_FLEET)
    assert status_messages(rendering) == {
        ("robot1", "/Temp/Sensor1"): "High temperature",
        ("site_a/robot7", "/Camera/Cam1"): "No frames received",
    }


def test_status_message_series_follow_the_configured_mode() -> None:
    every, _, _ = fleet_rendering(PAPER_FLEET, messages=MessageLabels("all"))
    assert status_messages(every)[("robot1", "/Power/Robot Battery")] == "Charge OK"
    assert len(status_messages(every)) == 3
    none, _, _ = fleet_rendering(PAPER_FLEET, messages=MessageLabels("none"))
    assert status_messages(none) == {}


def test_a_component_back_to_ok_loses_its_status_message_series() -> None:
    rendering, model, _ = fleet_rendering(PAPER_FLEET)
    recovered = PAPER_FLEET["robot1"][1]._replace(level=0, message="Normal")
    model.apply("robot1", DiagnosticArray(0, 0, "", (PAPER_FLEET["robot1"][0], recovered)), "dds")
    assert ("robot1", "/Temp/Sensor1") not in status_messages(rendering)


def status_message_levels(rendering: Rendering) -> dict[tuple[str, str], str]:
    """(robot, component) → level label of every status-message sample, checked against its component's."""
    levels: dict[tuple[str, str], float] = {}
    found = {}
    for family in text_string_to_metric_families(rendering.fast().decode()):
        for sample in family.samples:
            component = (sample.labels.get("robot", ""), sample.labels.get("component", ""))
            if sample.name == "ros_diagnostics_level":
                levels[component] = sample.value
            elif sample.name == "ros_diagnostics_status_message":
                assert Level[sample.labels["level"]] == levels[component], sample
                found[component] = sample.labels["level"]
    return found


def test_status_message_series_carry_the_component_level_now_stale_included() -> None:
    rendering, model, clock = fleet_rendering(PAPER_FLEET, messages=MessageLabels("all"))
    assert status_message_levels(rendering) == {
        ("robot1", "/Power/Robot Battery"): "OK",
        ("robot1", "/Temp/Sensor1"): "WARN",
        ("site_a/robot7", "/Camera/Cam1"): "ERROR",
    }
    # robot1's sensor is missing from its next message, robot7 sends none: both STALE after stale_after.
    clock.now += 6
    model.apply("robot1", DiagnosticArray(0, 0, "", (PAPER_FLEET["robot1"][0],)), "dds")
    assert status_message_levels(rendering) == {
        ("robot1", "/Power/Robot Battery"): "OK",
        ("robot1", "/Temp/Sensor1"): "STALE",
        ("site_a/robot7", "/Camera/Cam1"): "STALE",
    }
    assert status_messages(rendering)[("robot1", "/Temp/Sensor1")] == "High temperature"


@pytest.mark.parametrize(
    ("message", "length", "label"),
    [
        ("battery critically low (4 %)", 100, "battery critically low (4 %)"),
        ("x" * 100, 100, "x" * 100),
        ("x" * 101, 100, "x" * 99 + "…"),
        ("ロボット" * 30, 10, "ロボットロボットロ…"),
        ("🤖🤖🤖", 2, "🤖…"),
        ("abc", 1, "…"),
        ("lone \ud800 and \udfff surrogates", 100, "lone \ufffd and \ufffd surrogates"),
    ],
)
def test_message_label_is_cut_on_a_character_boundary_and_valid_utf8(
    message: str, length: int, label: str
) -> None:
    value = message_label_value(message, length)
    assert value == label
    assert len(value) <= length
    value.encode("utf-8")  # would raise on a surrogate


HOSTILE_MESSAGES = [*HOSTILE, "lone \ud800 surrogate", "end\\", 'end"', "x" * 100 + "\n"]


def test_hostile_status_messages_are_escaped_cut_and_parse_back() -> None:
    statuses = {
        "robot1": [
            DiagnosticStatus(2, f"/C{i}", message, "", ()) for i, message in enumerate(HOSTILE_MESSAGES)
        ]
    }
    rendering, _, _ = fleet_rendering(statuses, messages=MessageLabels("problems", 100))
    text = rendering.fast()
    found = status_messages(rendering)
    assert [found[("robot1", f"/C{i}")] for i in range(len(HOSTILE_MESSAGES))] == [
        message_label_value(message, 100) for message in HOSTILE_MESSAGES
    ]
    assert found[("robot1", "/C7")] == "lone \ufffd surrogate"
    assert found[("robot1", f"/C{len(HOSTILE_MESSAGES) - 1}")] == "x" * 99 + "…"
    result = subprocess.run(["promtool", "check", "metrics"], input=text, capture_output=True, timeout=60)
    assert result.returncode == 0, result.stdout.decode() + result.stderr.decode()


def test_external_url_is_exported_for_alert_links_only_when_configured() -> None:
    rendering, _, _ = fleet_rendering(PAPER_FLEET, external_url="https://ops.example/overseer")
    info = sample_value(rendering, "overseer_web_info", {"external_url": "https://ops.example/overseer"})
    assert info == 1
    plain, _, _ = fleet_rendering(PAPER_FLEET)
    assert "overseer_web_info{" not in plain.fast().decode()


def test_every_transport_shows_each_result_at_zero_and_zenoh_its_lost_samples_too() -> None:
    counts = dict(message_counts({("zenoh", "lost"): 3, ("dds", "received"): 2}, ["dds", "zenoh"]))
    assert counts[("zenoh", "lost")] == 3
    assert counts[("zenoh", "received")] == counts[("zenoh", "dropped")] == counts[("dds", "dropped")] == 0
    assert counts[("dds", "received")] == 2
    assert ("dds", "lost") not in counts  # DDS samples are not numbered here: nothing can be counted lost
