"""The inventory file: the documented example read as meant, and every mistake one line naming its place."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from overseer.inventory.file import RESERVED_LABELS, InventoryError, load_inventory, parse_inventory
from overseer.model import Expectation, Inventory, ListedRobot

# The example of docs/inventory.md: two sites, two models.
EXAMPLE = """
models:
  tb4:
    labels: {vendor: clearpath}
    expected:
      - /Power/Battery
      - {prefix: "/Wheels/", at_least: 4}
  arm:
    labels: {vendor: acme, model: arm-v2}
    expected:
      - {regex: "joint_[0-9]+: Temperature", at_least: 6}
robots:
  site_a/robot1:
    model: tb4
    labels: {site: site_a, team: logistics}
    expected: [/Arm/Gripper]
  site_a/arm1: {model: arm, labels: {site: site_a, team: assembly}}
  site_b/robot7: {model: tb4, labels: {site: site_b, team: inspection, vendor: rebuilt}}
  site_b/robot8: {model: tb4, labels: {site: site_b, team: inspection}}
  lab/test1:
"""


def test_the_documented_example_lists_every_robot_with_its_labels_and_expected_components() -> None:
    inventory = parse_inventory(EXAMPLE, "example")
    robot1 = inventory.robots["site_a/robot1"]
    assert robot1.labels == (
        ("model", "tb4"),
        ("site", "site_a"),
        ("team", "logistics"),
        ("vendor", "clearpath"),
    )
    assert robot1.expected == (
        Expectation("/Power/Battery", exact="/Power/Battery"),
        Expectation("/Wheels/*", prefix="/Wheels/", at_least=4),
        Expectation("/Arm/Gripper", exact="/Arm/Gripper"),
    )
    arm = inventory.robots["site_a/arm1"]
    assert dict(arm.labels)["model"] == "arm-v2"  # the model's own label wins over its name
    [joints] = arm.expected
    assert joints.pattern is not None and joints.pattern.pattern == "joint_[0-9]+: Temperature"
    assert (joints.at_least, joints.matches("joint_12: Temperature"), joints.matches("joint_1: Rate")) == (
        6,
        True,
        False,
    )
    assert dict(inventory.robots["site_b/robot7"].labels)["vendor"] == "rebuilt"  # the robot's wins
    assert inventory.robots["lab/test1"] == ListedRobot()
    # robots of one model share its expectations, not a copy each
    assert inventory.robots["site_b/robot7"].expected is inventory.robots["site_b/robot8"].expected


def test_an_empty_file_is_an_empty_inventory(tmp_path: Path) -> None:
    path = tmp_path / "inventory.yml"
    path.write_text("# nothing yet\n", encoding="utf-8")
    assert load_inventory(path) == Inventory()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("robots: [a, b]\n", "robots: expected a mapping, got ['a', 'b']"),
        ("robot: {}\n", "robot: unknown key (expected one of models, robots)"),
        (
            "robots:\n  r1: {labls: {}}\n",
            "robots.r1.labls: unknown key (expected one of expected, labels, model)",
        ),
        ("robots:\n  r1: {model: tb5}\n", "robots.r1.model: unknown model 'tb5' (known: none in models:)"),
        (
            "robots:\n  r1: {labels: {instance: x}}\n",
            "robots.r1.labels.instance: 'instance' is a label of Overseer's own series; name it otherwise",
        ),
        (
            "robots:\n  r1: {labels: {__site: x}}\n",
            "robots.r1.labels: '__site' is not a label name "
            "(letters, digits and _, not starting with a digit or __)",
        ),
        (
            "robots:\n  r1: {labels: {site-a: x}}\n",
            "robots.r1.labels: 'site-a' is not a label name "
            "(letters, digits and _, not starting with a digit or __)",
        ),
        (
            "robots:\n  r1: {labels: {team: 7}}\n",
            "robots.r1.labels.team: expected a non-empty string (quote it in YAML), got 7",
        ),
        (
            "robots:\n  r1: {labels: {team: ''}}\n",
            "robots.r1.labels.team: expected a non-empty string, got ''",
        ),
        (
            "robots:\n  r1: {expected: [{prefix: /W/, regex: x}]}\n",
            "robots.r1.expected[0]: expected one of name, prefix or regex, got prefix, regex",
        ),
        (
            "robots:\n  r1: {expected: [{regex: '(unclosed'}]}\n",
            "robots.r1.expected[0].regex: not a regular expression: missing ), unterminated subpattern at "
            "position 0",
        ),
        (
            "robots:\n  r1: {expected: [{name: /a, at_least: 2}]}\n",
            "robots.r1.expected[0].at_least: one name is one component; give a prefix or a regex",
        ),
        (
            "robots:\n  r1: {expected: [{prefix: /W/, at_least: 0}]}\n",
            "robots.r1.expected[0].at_least: expected a whole number from 1 to 10000, got 0",
        ),
        (
            "robots:\n  r1: {expected: /a}\n",
            "robots.r1.expected: expected a list of component names or mappings",
        ),
        ("models:\n  m: {expected: [{}]}\n", "models.m.expected[0]: expected one of name, prefix or regex"),
        ("robots:\n  7: {}\n", "robots: 7 is not a name (a printable string)"),
    ],
)
def test_a_mistake_is_one_line_naming_the_file_the_robot_and_the_key(text: str, message: str) -> None:
    with pytest.raises(InventoryError) as raised:
        parse_inventory(text, "fleet.yml")
    assert str(raised.value).startswith(f"inventory.file 'fleet.yml': {message}"), str(raised.value)
    assert "\n" not in str(raised.value)


def test_a_robot_listed_twice_is_refused_rather_than_the_first_one_lost() -> None:
    with pytest.raises(InventoryError, match=r"not valid YAML: .*'site_a/r1' is given twice"):
        parse_inventory("robots:\n  site_a/r1: {}\n  site_b/r2: {}\n  site_a/r1: {model: x}\n", "f")


def test_yaml_that_does_not_parse_and_a_file_that_cannot_be_read_say_so(tmp_path: Path) -> None:
    with pytest.raises(InventoryError, match=r"^inventory.file 'f': not valid YAML: "):
        parse_inventory("robots: {r1: [}\n", "f")
    with pytest.raises(InventoryError, match=r"^inventory.file: cannot read '.*absent.yml': No such file"):
        load_inventory(tmp_path / "absent.yml")
    binary = tmp_path / "binary.yml"
    binary.write_bytes(b"\xff\xfe\x00robots")
    with pytest.raises(InventoryError, match="not UTF-8 text"):
        load_inventory(binary)


def test_no_reserved_label_is_a_valid_prometheus_label_of_ours_to_give() -> None:
    assert all(re.fullmatch(r"[a-z_]+", name) for name in RESERVED_LABELS)
    assert {"robot", "component", "hardware_id", "instance", "job", "severity"} <= RESERVED_LABELS


def test_yaml_reads_as_a_safe_load_would_merge_keys_and_anchors_included() -> None:
    text = """
models:
  base: &base {labels: {vendor: acme}, expected: [/Power]}
  tb4:
    <<: *base
    labels: {vendor: clearpath}
robots:
  r1: {model: tb4, labels: {site: a, note: "007"}}
  r2: {model: base, labels: *labels}
"""
    with pytest.raises(InventoryError, match="not valid YAML: found undefined alias"):
        parse_inventory(text, "f")
    inventory = parse_inventory(text.replace("*labels", "{site: b}"), "f")
    assert dict(inventory.robots["r1"].labels) == {
        "model": "tb4",
        "vendor": "clearpath",
        "site": "a",
        "note": "007",
    }
    assert [e.exact for e in inventory.robots["r1"].expected] == ["/Power"]
    with pytest.raises(
        InventoryError,
        match=r"robots.r1.labels.enabled: expected a non-empty string \(quote it in YAML\), got True",
    ):
        parse_inventory("robots:\n  r1: {labels: {enabled: yes}}\n", "f")  # YAML 1.1's yes is true
    with pytest.raises(InventoryError, match=r"robots.r1.labels: True is not a label name"):
        parse_inventory("robots:\n  r1: {labels: {on: x}}\n", "f")  # and so is its on
    with pytest.raises(InventoryError, match="found an unhashable key"):
        parse_inventory("robots:\n  ? [a, b]\n  : {}\n", "f")
