"""Every configuration key has its entry in its section's table: a flag (or why not), its documentation.

The tables (`OPTIONS` in each module of `overseer.config`) are where `overseer run` takes its flags from
and the reference in docs/configuration.md is written from; these tests hold the tables to the keys the
sections really read, the flags to the tables, and the reference to both.
"""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from overseer.cli import COMMANDS, parser_of
from overseer.config import (
    ConfigError,
    config_from_dict,
    dds,
    events,
    fleet,
    ingest,
    load_config,
    maintenance,
    metrics,
    ros1,
    ros2,
    web,
    zenoh,
)
from overseer.config.loading import ALL_OPTIONS
from overseer.config.options import Option, flag_names, naming_the_flag, overrides
from overseer.config.reference import BEGIN, END, reference, with_reference
from overseer.model import FleetLimits
from testbed.paths import REPO

CONFIGURATION_DOCS = REPO / "docs" / "configuration.md"
NONSENSE = {"not": "a value any key takes"}


def test_every_option_is_a_key_its_section_reads_and_says_so_when_it_is_bad(tmp_path: Path) -> None:
    # Sections that need others of their keys to be valid first get those (real files where needed).
    ca = tmp_path / "ca.crt"
    command = ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj", "/CN=ca"]
    made = subprocess.run(
        [*command, "-keyout", str(tmp_path / "ca.key"), "-out", str(ca)],
        capture_output=True,
        check=False,
    )
    assert made.returncode == 0, made.stderr
    password = tmp_path / "password"
    password.write_text("secret\n", encoding="utf-8")
    valid: dict[str, dict[str, Any]] = {
        "icinga2": {
            "url": "https://icinga:5665",
            "ca_file": str(ca),
            "username": "u",
            "password_file": str(password),
        },
        "alertmanager": {"url": "http://alertmanager:9093", "username": "u"},
    }
    for entry in ALL_OPTIONS:
        section, _, key = entry.key.partition(".")
        raw: dict[str, Any] = {section: NONSENSE}  # a key at the top
        if key:
            raw = {section: {**valid.get(section, {}), key: NONSENSE}}
        with pytest.raises(ConfigError) as raised:
            config_from_dict(raw)
        assert str(raised.value).startswith(entry.key), (entry.key, str(raised.value))


@pytest.mark.parametrize(
    ("module", "record"),
    [
        (web, web.WebConfig),
        (dds, dds.DdsConfig),
        (ros1, ros1.Ros1Config),
        (ros2, ros2.Ros2Config),
        (zenoh, zenoh.ZenohConfig),
        (fleet, FleetLimits),
        (metrics, metrics.MetricsConfig),
        (events, events.EventsConfig),
        (ingest, ingest.IngestConfig),
        (maintenance, maintenance.MaintenanceConfig),
    ],
)
def test_every_field_of_a_section_is_in_its_table(module: Any, record: type) -> None:
    assert {field.name for field in dataclasses.fields(record)} <= module.KEYS


def test_every_option_has_a_flag_or_says_why_not_and_a_meaning() -> None:
    keys = [entry.key for entry in ALL_OPTIONS]
    assert len(keys) == len(set(keys))
    for entry in ALL_OPTIONS:
        assert entry.meaning and entry.default, entry.key
        assert bool(entry.flags) != bool(entry.file_only), entry.key
    names = flag_names(ALL_OPTIONS)
    assert len(names) == len(set(names))


def test_the_flags_of_overseer_run_are_the_tables_and_config_file() -> None:
    help_text = subprocess.run(
        [sys.executable, "-m", "overseer.cli", "run", "--help"], capture_output=True, text=True, check=True
    ).stdout
    shown = {word.rstrip(",") for word in help_text.split() if word.startswith("--")}
    assert shown == {*flag_names(ALL_OPTIONS), "--config.file", "--help"}


def test_the_reference_in_the_docs_is_the_one_the_tables_write() -> None:
    document = CONFIGURATION_DOCS.read_text(encoding="utf-8")
    assert BEGIN in document and END in document, "make docs writes the reference between the markers"
    assert with_reference(document) == document, "the reference is stale: run make docs"
    written = reference()
    for entry in ALL_OPTIONS:
        assert f"`{entry.key.partition('.')[2] or entry.key}`" in written
        assert all(flag.name in written for flag in entry.flags), entry.key


def test_a_flag_gives_its_key_the_value_as_text_and_the_section_parses_it() -> None:
    flags = [
        "--fleet.stale-after=2m",
        "--fleet.robot-timeout=3m",
        "--fleet.expire-after=2h",
        "--dds.domain=7",
    ]
    flags += ["--dds.domain=8", "--dds.disabled", "--ingest.workers=3"]
    given = overrides(parser_of(COMMANDS).parse_args(["run", *flags]), ALL_OPTIONS)
    assert given == {
        "fleet.stale_after": "2m",
        "fleet.robot_timeout": "3m",
        "fleet.expire_after": "2h",
        "dds.domains": ["7", "8"],
        "dds.enabled": False,
        "ingest.workers": "3",
    }
    config = load_config(None, given, environ={})
    assert (config.fleet.stale_after, [d.id for d in config.dds.domains]) == (120.0, [7, 8])
    assert (config.dds.enabled, config.ingest.workers) == (False, 3)


def test_a_flag_spells_a_number_or_boolean_that_a_quoted_value_in_the_file_does_not(tmp_path: Path) -> None:
    flags = ["--fleet.max-robots=20", "--metrics.level-changes=false", "--dds.max-participant-index=8"]
    config = load_config(None, overrides(parser_of(COMMANDS).parse_args(["run", *flags]), ALL_OPTIONS), {})
    assert (config.fleet.max_robots, config.metrics.level_changes, config.dds.max_participant_index) == (
        20,
        False,
        8,
    )
    for text, message in (
        ("fleet:\n  max_robots: '20'\n", "fleet.max_robots: expected a positive integer, got '20'"),
        (
            "metrics:\n  level_changes: 'false'\n",
            "metrics.level_changes: expected true or false, got 'false'",
        ),
    ):
        path = tmp_path / "overseer.yml"
        path.write_text(text, encoding="utf-8")
        with pytest.raises(ConfigError, match=re.escape(message)):
            load_config(path, {}, environ={})


def test_a_bad_flag_is_named_by_its_key_as_a_bad_file_would_be() -> None:
    args = parser_of(COMMANDS).parse_args(["run", "--fleet.stale-after=soon"])
    with pytest.raises(
        ConfigError, match=r"^fleet\.stale_after: expected a duration such as 5s, got 'soon'$"
    ):
        load_config(None, overrides(args, ALL_OPTIONS), environ={})


def test_the_error_of_a_bad_flag_names_the_flag_typed_and_its_key() -> None:
    message = "fleet.stale_after: expected a duration such as 5s, got 'soon'"
    typed = parser_of(COMMANDS).parse_args(["run", "--fleet.stale-after=soon"])
    assert naming_the_flag(message, typed, ALL_OPTIONS) == (
        "--fleet.stale-after (fleet.stale_after): expected a duration such as 5s, got 'soon'"
    )
    from_the_file = parser_of(COMMANDS).parse_args(["run"])
    assert naming_the_flag(message, from_the_file, ALL_OPTIONS) == message
    peers = parser_of(COMMANDS).parse_args(["run", "--dds.peer=a", "--dds.peer=:0"])
    assert (
        naming_the_flag("dds.peers[1]: bad port", peers, ALL_OPTIONS) == "--dds.peer (dds.peers[1]): bad port"
    )


def test_a_file_only_option_has_no_flag_and_is_documented_so() -> None:
    entry = next(option for option in ALL_OPTIONS if option.key == "maintenance.windows")
    assert isinstance(entry, Option) and not entry.flags
    assert f"none: {entry.file_only}" in reference()
