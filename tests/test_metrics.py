"""The /metrics view: the metric contract, golden exposition, label escaping, promtool."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from prometheus_client import generate_latest
from prometheus_client.parser import text_string_to_metric_families
from prometheus_client.registry import CollectorRegistry

from overseer.codec import compiled
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.serve.metrics import FleetCollector, numeric_value

GOLDEN = Path(__file__).parent / "golden" / "metrics.txt"
CONTRACT = {
    "ros_diagnostics_level": "gauge",
    "ros_diagnostics_robot_level": "gauge",
    "ros_diagnostics_robot_up": "gauge",
    "ros_diagnostics_robot_last_message_timestamp_seconds": "gauge",
    "ros_diagnostics_level_changes": "counter",
    "ros_diagnostics_value": "gauge",
    "overseer_messages": "counter",
    "overseer_build_info": "gauge",
}


class Clock:
    """A hand-moved clock."""

    def __init__(self) -> None:
        """Start at a fixed unix time so the exposition is reproducible."""
        self.now = 1_700_000_000.0

    def __call__(self) -> float:
        """The current time."""
        return self.now


def fleet_registry(
    statuses: dict[str, list[DiagnosticStatus]], value_keys: str = ".*"
) -> tuple[CollectorRegistry, FleetModel, Clock]:
    clock = Clock()
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=10, expire_after=60), clock=clock)
    for robot, items in statuses.items():
        model.apply(robot, DiagnosticArray(0, 0, "", tuple(items)), "dds")
    registry = CollectorRegistry()
    registry.register(FleetCollector(model, re.compile(value_keys), ["dds"]))
    return registry, model, clock


PAPER_FLEET = {
    "robot1": [
        DiagnosticStatus(
            0, "/Power/Robot Battery", "Charge OK", "power1", (("voltage", "12.6 V"), ("note", "fine"))
        ),
        DiagnosticStatus(1, "/Temp/Sensor1", "High temperature", "temp1", (("temperature", "71.0"),)),
    ],
    "site_a/robot7": [DiagnosticStatus(2, "/Camera/Cam1", "No frames received", "camera1", (("fps", "0"),))],
}


def test_exposition_matches_golden_file() -> None:
    registry, model, clock = fleet_registry(PAPER_FLEET)
    clock.now += 6
    model.apply("robot1", DiagnosticArray(0, 0, "", (PAPER_FLEET["robot1"][0],)), "dds")
    model.count_message("dds", "decode_error")
    text = generate_latest(registry).decode()
    text = text.replace('version="' + _version() + '"', 'version="VERSION"')
    text = text.replace('codec="' + compiled.implementation() + '"', 'codec="CODEC"')
    assert text == GOLDEN.read_text(encoding="utf-8")


def _version() -> str:
    from overseer import __version__

    return __version__


def test_contract_names_and_types_are_exported() -> None:
    registry, _, _ = fleet_registry(PAPER_FLEET)
    families = {f.name: f.type for f in text_string_to_metric_families(generate_latest(registry).decode())}
    for name, kind in CONTRACT.items():
        assert families.get(name) == kind, name


def test_levels_up_and_robot_level_samples() -> None:
    registry, _, _ = fleet_registry(PAPER_FLEET)
    battery = {"robot": "robot1", "component": "/Power/Robot Battery", "hardware_id": "power1"}
    assert registry.get_sample_value("ros_diagnostics_level", battery) == 0
    assert registry.get_sample_value("ros_diagnostics_robot_level", {"robot": "robot1"}) == 1
    assert registry.get_sample_value("ros_diagnostics_robot_level", {"robot": "site_a/robot7"}) == 2
    assert registry.get_sample_value("ros_diagnostics_robot_up", {"robot": "robot1"}) == 1
    assert registry.get_sample_value("ros_diagnostics_value", {**battery, "key": "voltage"}) == 12.6
    assert registry.get_sample_value("ros_diagnostics_value", {**battery, "key": "note"}) is None


def test_only_allowed_value_keys_are_exported() -> None:
    registry, _, _ = fleet_registry(PAPER_FLEET, value_keys="temperature|fps")
    text = generate_latest(registry).decode()
    assert 'key="temperature"' in text and 'key="fps"' in text
    assert 'key="voltage"' not in text


def test_forgotten_robot_disappears_from_exposition() -> None:
    registry, model, clock = fleet_registry(PAPER_FLEET)
    clock.now += 61
    model.apply("robot1", DiagnosticArray(0, 0, "", tuple(PAPER_FLEET["robot1"])), "dds")
    model.expire()
    text = generate_latest(registry).decode()
    assert "site_a/robot7" not in text
    assert 'robot="robot1"' in text


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


def hostile_registry() -> CollectorRegistry:
    statuses = {
        f"robot{i}/{name}": [
            DiagnosticStatus(
                i % 4, name, name, name, ((name, "1.5"), ("nan", "nan"), ("inf", "inf"), ("neg", "-inf"))
            )
        ]
        for i, name in enumerate(HOSTILE)
    }
    registry, _, _ = fleet_registry(statuses)
    return registry


def test_hostile_names_are_escaped_and_parse_back() -> None:
    text = generate_latest(hostile_registry()).decode()
    families = {f.name: f for f in text_string_to_metric_families(text)}
    components = {s.labels["component"] for s in families["ros_diagnostics_level"].samples}
    assert components == set(HOSTILE)


def test_hostile_exposition_passes_promtool() -> None:
    text = generate_latest(hostile_registry())
    result = subprocess.run(["promtool", "check", "metrics"], input=text, capture_output=True, timeout=60)
    assert result.returncode == 0, result.stdout.decode() + result.stderr.decode()


def test_golden_exposition_passes_promtool() -> None:
    result = subprocess.run(
        ["promtool", "check", "metrics"], input=GOLDEN.read_bytes(), capture_output=True, timeout=60
    )
    assert result.returncode == 0, result.stdout.decode() + result.stderr.decode()
