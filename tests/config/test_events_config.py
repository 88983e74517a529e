"""The event history's configuration: the `events:` section, its flags, `--log.format`, and their errors."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
from pathlib import Path

import pytest

from overseer.config import ConfigError, load_config
from overseer.config.events import EventsConfig
from overseer.log_format import JsonFormatter
from testbed.processes import overseer_command


def test_defaults_are_documented_ones() -> None:
    config = load_config(None)
    assert config.events == EventsConfig(True, "overseer-events.db", 30 * 86400.0, 1_000_000_000)
    assert config.log_format == "text"


def test_the_section_and_the_flags_set_every_key(tmp_path: Path) -> None:
    path = tmp_path / "overseer.yml"
    path.write_text(
        "events:\n  enabled: false\n  path: /var/lib/x.db\n  retention: 7d\n  max_size: 2GiB\n"
        "log_format: json\n"
    )
    config = load_config(path)
    assert config.events == EventsConfig(False, "/var/lib/x.db", 7 * 86400.0, 2 * 1024**3)
    assert config.log_format == "json"
    flags = load_config(path, {"events.max_size": 500_000_000, "events.path": "other.db"})
    assert (flags.events.max_size, flags.events.path, flags.events.enabled) == (
        500_000_000,
        "other.db",
        False,
    )


@pytest.mark.parametrize(
    ("yaml_text", "message"),
    [
        ("events: {enabled: yes please}", "events.enabled: expected true or false, got 'yes please'"),
        ("events: {retention: forever}", "events.retention: expected a duration such as 5s, got 'forever'"),
        (
            "events: {max_size: 12 apples}",
            "events.max_size: expected a size such as 500MB or 1GB, got '12 apples'",
        ),
        ("events: {max_size: 10kB}", "events.max_size: must be at least 1MB, got '10kB'"),
        ("events: {path: ''}", "events.path: expected a non-empty string, got ''"),
        (
            "events: {size: 1GB}",
            "events.size: unknown key (expected one of enabled, max_size, path, retention)",
        ),
        ("log_format: xml", "log_format: expected text or json, got 'xml'"),
    ],
)
def test_bad_values_name_their_key(tmp_path: Path, yaml_text: str, message: str) -> None:
    path = tmp_path / "overseer.yml"
    path.write_text(yaml_text + "\n")
    with pytest.raises(ConfigError) as error:
        load_config(path)
    assert str(error.value) == message


@pytest.mark.servers
@pytest.mark.parametrize(
    ("flag", "message"),
    [
        (
            "--events.max-size=huge",
            "--events.max-size (events.max_size): expected a size such as 500MB or 1GB, got 'huge'",
        ),
        (
            "--events.retention=0s",
            "--events.retention (events.retention): must be a positive duration, got '0s'",
        ),
    ],
)
def test_bad_flags_stop_the_exporter_with_one_line(flag: str, message: str) -> None:
    result = subprocess.run([*overseer_command(), "run", flag], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr.strip() == f"overseer run: configuration error: {message}"


def test_json_log_lines_carry_extra_fields_and_exceptions() -> None:
    record = logging.LogRecord("overseer.events", logging.INFO, __file__, 1, "event %s", ("x",), None)
    record.event = {"id": 1, "message": 'quote" and\nnewline'}
    line = JsonFormatter().format(record)
    assert "\n" not in line
    parsed = json.loads(line)
    assert (
        parsed["logger"] == "overseer.events" and parsed["level"] == "info" and parsed["message"] == "event x"
    )
    assert parsed["event"] == {"id": 1, "message": 'quote" and\nnewline'}
    assert parsed["time"].endswith("Z")
    try:
        raise ValueError("boom")
    except ValueError:
        failed = logging.LogRecord("overseer", logging.ERROR, __file__, 1, "failed", None, sys.exc_info())
    assert "ValueError: boom" in json.loads(JsonFormatter().format(failed))["exception"]
