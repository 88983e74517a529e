"""The shipped alert rules and Alertmanager example, checked by promtool and amtool and read like a mixin."""

from __future__ import annotations

import json
import re
import subprocess
from typing import Any

import pytest
import yaml

from testbed.paths import REPO
from testbed.prometheus import DEPLOY_PROMETHEUS, load_rules, parse_duration, selectors

RULES_DIR = REPO / "alert_rules"
DEFAULT_RULES = RULES_DIR / "overseer.rules.yml"
FAST_RULES = RULES_DIR / "overseer-fast.rules.yml"
RULE_TESTS = RULES_DIR / "overseer.rules.test.yml"
ALERTMANAGER_EXAMPLE = RULES_DIR / "alertmanager.example.yml"
RUNBOOK = REPO / "docs" / "runbook.md"

RECEIVER_OF_SEVERITY = {"critical": "fleet-critical", "warning": "fleet-warning"}
JOB_MATCHER = 'job="overseer"'
RECORDING_RULE_NAME = re.compile(r"[a-z]+:[a-z_]+:[a-z0-9_]+")
_MATCHER = re.compile(r'(\w+)(=~|!~|!=|=)"(.*)"')


def run(*args: str) -> subprocess.CompletedProcess[str]:
    """Run a command to completion, capturing its output."""
    return subprocess.run(args, capture_output=True, text=True, timeout=60, check=False)


def alerts(path: Any = DEFAULT_RULES) -> dict[str, dict[str, Any]]:
    """The alerting rules of a rule file by name."""
    return {rule["alert"]: rule for rule in load_rules(path) if "alert" in rule}


def matches(matcher: str, labels: dict[str, str]) -> bool:
    """Whether an Alertmanager matcher such as `alertname=~"Ros.+"` matches a label set."""
    parsed = _MATCHER.fullmatch(matcher)
    assert parsed, f"cannot read matcher {matcher!r}"
    name, operator, value = parsed.groups()
    actual = labels.get(name, "")
    equal = re.fullmatch(value, actual) is not None if "~" in operator else actual == value
    return equal != operator.startswith("!")


@pytest.mark.parametrize("rules", [DEFAULT_RULES, FAST_RULES], ids=lambda path: path.name)
def test_promtool_accepts_the_rules(rules: Any) -> None:
    result = run("promtool", "check", "rules", str(rules))
    assert result.returncode == 0, result.stdout + result.stderr


def test_promtool_unit_tests_next_to_the_rules_pass() -> None:
    result = run("promtool", "test", "rules", str(RULE_TESTS))
    assert result.returncode == 0, result.stdout + result.stderr


def test_every_alert_has_a_firing_and_a_quiet_unit_test() -> None:
    document = yaml.safe_load(RULE_TESTS.read_text(encoding="utf-8"))
    cases = [case for test in document["tests"] for case in test.get("alert_rule_test", [])]
    firing = {case["alertname"] for case in cases if case["exp_alerts"]}
    quiet = {case["alertname"] for case in cases if not case["exp_alerts"]}
    assert set(alerts()) - firing == set(), "alerts without a firing test"
    assert set(alerts()) - quiet == set(), "alerts without a not-firing test"


@pytest.mark.parametrize("rules", [DEFAULT_RULES, FAST_RULES], ids=lambda path: path.name)
def test_every_alert_has_for_severity_summary_description_and_a_runbook_section(rules: Any) -> None:
    runbook_anchors = {
        line.removeprefix("## ").strip().lower()
        for line in RUNBOOK.read_text().splitlines()
        if line.startswith("## ")
    }
    for name, rule in alerts(rules).items():
        assert parse_duration(rule["for"]) > 0, name
        assert rule["labels"]["severity"] in RECEIVER_OF_SEVERITY, name
        annotations = rule["annotations"]
        assert annotations["summary"] and annotations["description"], name
        assert annotations["runbook_url"] == f"docs/runbook.md#{name.lower()}", name
        assert name.lower() in runbook_anchors, f"docs/runbook.md has no section for {name}"


# The alerts of a robot that does not speak: they inhibit its other alerts, and list no components.
ROBOT_DOWN_ALERTS = {"RosRobotDown", "RosRobotNeverHeard"}


def robot_alerts(path: Any = DEFAULT_RULES) -> dict[str, dict[str, Any]]:
    """The alerts about one robot: those that link to its page on the status page."""
    return {name: rule for name, rule in alerts(path).items() if "status_page_url" in rule["annotations"]}


def test_robot_alerts_name_the_robot_and_list_its_components_from_that_robot_alone() -> None:
    assert set(robot_alerts()) == {
        "RosRobotError",
        "RosRobotWarning",
        "RosRobotStale",
        "RosRobotDown",
        "RosRobotNeverHeard",
        "RosRobotFlapping",
    }
    for name, rule in robot_alerts().items():
        annotations = rule["annotations"]
        assert "{{ $labels.robot }}" in annotations["summary"], name
        if name in ROBOT_DOWN_ALERTS:
            continue
        assert "/api/v1/robots/{{ $labels.robot }}" in annotations["description"], name
        queries = re.findall(r"printf `([^`]*)`", annotations["message"])
        assert queries, name
        for query in queries:
            for selector in selectors(query):
                assert "instance=%q,robot=%q" in selector.matchers, f"{name}: {selector}"


def test_only_the_message_annotation_queries_and_the_robot_down_alerts_not_at_all() -> None:
    # Prometheus expands every annotation of every pending or firing alert at every evaluation: at fleet scale
    # each query there costs once per robot in trouble.
    for name, rule in alerts().items():
        for annotation, text in rule["annotations"].items():
            if annotation != "message":
                assert "| query" not in text, f"{name} {annotation}"
    for name in ROBOT_DOWN_ALERTS:
        assert "message" not in alerts()[name]["annotations"], name


ALERT_LABELS = "robot:ros_diagnostics_robot_info:alert_labels"
INVENTORY_LABELS = ("site", "model", "team")


def test_every_robot_alert_takes_its_labels_from_the_one_per_robot_recording_rule() -> None:
    # The rule carries the link label and the inventory labels; a robot it leaves out raises no alert.
    join = f'* on (job, instance, robot) group_right {ALERT_LABELS}{{job="overseer"}}'
    for name, rule in robot_alerts().items():
        assert rule["expr"].endswith(join), name


def test_the_inventory_labels_on_alerts_are_named_in_one_place_the_join_with_the_info_series() -> None:
    (labels_rule,) = [rule for rule in load_rules(DEFAULT_RULES) if rule.get("record") == ALERT_LABELS]
    copied = re.search(r"group_left \(([^)]*)\)\s*\(\s*ros_diagnostics_robot_info\{", labels_rule["expr"])
    assert copied, labels_rule["expr"]
    assert tuple(copied.group(1).split(", ")) == INVENTORY_LABELS
    for rule in load_rules(DEFAULT_RULES):
        if rule.get("record") != ALERT_LABELS:
            named = [label for label in INVENTORY_LABELS if re.search(rf"\b{label}\b", rule["expr"])]
            assert not named, f"{rule.get('alert') or rule['record']} names {named}"


COMPONENT_SERIES = {"ros_diagnostics_level", "ros_diagnostics_level_changes_total", "ros_diagnostics_value"}


@pytest.mark.parametrize("rules", [DEFAULT_RULES, FAST_RULES], ids=lambda path: path.name)
def test_only_flapping_reads_every_component_and_every_five_minutes(rules: Any) -> None:
    # At 10,000 robots x 50 one pass over every component series takes 12-14 % of a minute on its own: the
    # component counts come from the exporter's per-robot counts, and flapping alone reads components.
    document = yaml.safe_load(rules.read_text(encoding="utf-8"))
    reading_components = {}
    for group in document["groups"]:
        read = {selector.metric for rule in group["rules"] for selector in selectors(rule["expr"])}
        if read & COMPONENT_SERIES:
            reading_components[group["name"]] = parse_duration(group["interval"])
    assert reading_components == {"overseer.flapping": 300}


def test_every_selector_selects_the_overseer_job() -> None:
    for rule in load_rules(DEFAULT_RULES):
        for selector in selectors(rule["expr"]):
            assert JOB_MATCHER in selector.matchers, f"{rule.get('alert') or rule['record']}: {selector}"


def test_recording_rules_are_named_level_metric_operations_after_the_metric_they_aggregate() -> None:
    recording = [rule for rule in load_rules(DEFAULT_RULES) if "record" in rule]
    assert recording
    for rule in recording:
        assert RECORDING_RULE_NAME.fullmatch(rule["record"]), rule["record"]
        metric = rule["record"].split(":")[1]
        # Read directly, or through another recording rule of the same metric.
        read = {
            selector.metric.split(":")[1] if ":" in selector.metric else selector.metric
            for selector in selectors(rule["expr"])
        }
        assert metric in read, rule["record"]


def test_fast_profile_is_the_default_profile_with_shorter_for() -> None:
    default, fast = load_rules(DEFAULT_RULES), load_rules(FAST_RULES)
    assert [{**rule, "for": None} for rule in fast] == [{**rule, "for": None} for rule in default]
    for name, rule in alerts(FAST_RULES).items():
        assert parse_duration(rule["for"]) < parse_duration(alerts()[name]["for"]), name


def margin_and_intervals(config: str, alert: str) -> tuple[float, float]:
    """How much sooner `alert` fires than RosRobotStale, and a scrape plus an evaluation, in `config` (s)."""
    path = DEPLOY_PROMETHEUS / config
    settings = yaml.safe_load(path.read_text(encoding="utf-8"))
    (rule_file,) = settings["rule_files"]
    rule = alerts(path.parent / rule_file)
    margin = parse_duration(rule["RosRobotStale"]["for"]) - parse_duration(rule[alert]["for"])
    intervals = parse_duration(settings["global"]["scrape_interval"]) + parse_duration(
        settings["global"]["evaluation_interval"]
    )
    return margin, intervals


@pytest.mark.parametrize("config", ["prometheus.yml", "prometheus-fast.yml"])
def test_robot_down_fires_before_its_stale_alert(config: str) -> None:
    # A stopped robot's components turn STALE (stale_after 5s) before it counts as down (robot_timeout 10s).
    # RosRobotDown must still fire first, by more than that gap plus one scrape and one evaluation, so that
    # Alertmanager inhibits RosRobotStale before it sends it.
    margin, intervals = margin_and_intervals(config, "RosRobotDown")
    assert margin > (10 - 5) + intervals


@pytest.mark.parametrize("config", ["prometheus.yml", "prometheus-fast.yml"])
def test_robot_never_heard_fires_before_its_stale_alert(config: str) -> None:
    # A robot never heard is STALE from the scrape that first shows it: RosRobotNeverHeard must fire more than
    # one scrape and one evaluation before RosRobotStale, so that Alertmanager inhibits RosRobotStale.
    margin, intervals = margin_and_intervals(config, "RosRobotNeverHeard")
    assert margin > intervals


def test_amtool_accepts_the_alertmanager_example() -> None:
    result = run("amtool", "check-config", str(ALERTMANAGER_EXAMPLE))
    assert result.returncode == 0, result.stdout + result.stderr


@pytest.mark.parametrize("name", sorted(alerts()))
def test_every_alert_routes_to_the_receiver_of_its_severity(name: str) -> None:
    severity = alerts()[name]["labels"]["severity"]
    receiver = RECEIVER_OF_SEVERITY[severity]
    result = run(
        "amtool",
        "config",
        "routes",
        "test",
        f"--config.file={ALERTMANAGER_EXAMPLE}",
        f"--verify.receivers={receiver}",
        f"alertname={name}",
        f"severity={severity}",
        "robot=robot1",
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.strip() == receiver


def routes(route: dict[str, Any]) -> list[dict[str, Any]]:
    """A route and every route beneath it."""
    return [route, *(child for sub in route.get("routes", []) for child in routes(sub))]


def test_alertmanager_groups_by_robot() -> None:
    config = yaml.safe_load(ALERTMANAGER_EXAMPLE.read_text(encoding="utf-8"))
    assert config["route"]["group_by"] == ["robot"]
    assert all(route.get("group_by", ["robot"]) == ["robot"] for route in routes(config["route"]))


def equality(matcher: str) -> tuple[str, str]:
    """The label and value an equality matcher such as `site="site_a"` asks for."""
    parsed = _MATCHER.fullmatch(matcher)
    assert parsed and parsed.group(2) == "=", f"not an equality matcher: {matcher}"
    return parsed.group(1), parsed.group(3)


def site_and_team_routes() -> list[tuple[str, tuple[str, str], str]]:
    """(severity, (label, value), receiver) of every route beneath a severity route of the example."""
    config = yaml.safe_load(ALERTMANAGER_EXAMPLE.read_text(encoding="utf-8"))
    found = []
    for parent in config["route"]["routes"]:
        ((_, severity),) = [equality(matcher) for matcher in parent["matchers"]]
        for child in parent.get("routes", []):
            (matcher,) = child["matchers"]
            found.append((severity, equality(matcher), child["receiver"]))
    return found


def test_the_example_routes_critical_alerts_by_site_and_warnings_by_team() -> None:
    routed_by = {(severity, label) for severity, (label, _), _ in site_and_team_routes()}
    assert routed_by == {("critical", "site"), ("warning", "team")}


@pytest.mark.parametrize(("severity", "label", "receiver"), site_and_team_routes())
def test_every_robot_alert_of_a_site_or_team_reaches_its_receiver(
    severity: str, label: tuple[str, str], receiver: str
) -> None:
    inventory = {"site": "site_a", "model": "tb4", "team": "logistics"} | dict([label])
    for name, rule in robot_alerts().items():
        if rule["labels"]["severity"] != severity:
            continue
        result = run(
            "amtool",
            "config",
            "routes",
            "test",
            f"--config.file={ALERTMANAGER_EXAMPLE}",
            f"--verify.receivers={receiver}",
            f"alertname={name}",
            f"severity={severity}",
            "robot=robot1",
            *(f"{key}={value}" for key, value in inventory.items()),
        )
        assert result.returncode == 0, f"{name}: {result.stdout}{result.stderr}"


@pytest.mark.parametrize("source", sorted(ROBOT_DOWN_ALERTS))
def test_a_down_robot_inhibits_exactly_the_other_alerts_of_the_same_robot(source: str) -> None:
    config = yaml.safe_load(ALERTMANAGER_EXAMPLE.read_text(encoding="utf-8"))
    robot_down = {"alertname": source, **alerts()[source]["labels"]}
    inhibited = set()
    for rule in config["inhibit_rules"]:
        if all(matches(matcher, robot_down) for matcher in rule["source_matchers"]):
            assert {"instance", "robot"} <= set(rule["equal"])
            inhibited |= {
                name
                for name, alert in alerts().items()
                if all(
                    matches(matcher, {"alertname": name, **alert["labels"]})
                    for matcher in rule["target_matchers"]
                )
            }
    assert inhibited == set(robot_alerts()) - ROBOT_DOWN_ALERTS


@pytest.mark.parametrize("rules", [DEFAULT_RULES, FAST_RULES], ids=lambda path: path.name)
def test_robot_alerts_carry_message_and_robot_link_in_annotations_never_in_labels(rules: Any) -> None:
    for name, rule in alerts(rules).items():
        assert "message" not in rule.get("labels", {}), name
    for name, rule in robot_alerts(rules).items():
        annotations = rule["annotations"]
        if name in {"RosRobotError", "RosRobotWarning"}:
            assert "ros_diagnostics_status_message{" in annotations["message"], name
            assert "$c.Labels.message" in annotations["message"], name
        assert "$labels.external_url" in annotations["status_page_url"], name
        link = '/?robot={{ reReplaceAll `\\+` "%20" ($labels.robot | urlquery) }}'
        assert link in annotations["status_page_url"], name


@pytest.mark.parametrize("rules", [DEFAULT_RULES, FAST_RULES], ids=lambda path: path.name)
def test_template_queries_quote_label_values_with_q_so_hostile_names_stay_one_string(rules: Any) -> None:
    for name, rule in alerts(rules).items():
        for annotation, text in rule["annotations"].items():
            if "| query" in text:
                assert '"%s"' not in text and "=%q" in text, f"{name} {annotation}"


TEMPLATES = RULES_DIR / "overseer.tmpl"


def notification(*alerts: dict[str, Any], status: str = "firing") -> dict[str, Any]:
    """Alertmanager's template data (the webhook's JSON) for one notification of robot alpha."""
    return {
        "receiver": "fleet-critical",
        "status": status,
        "alerts": [{"status": status, "startsAt": "2026-11-23T09:00:00Z", **alert} for alert in alerts],
        "groupLabels": {"robot": "alpha"},
        "commonLabels": {},
        "commonAnnotations": {},
        "externalURL": "http://alertmanager:9093",
    }


BATTERY_ERROR = {
    "labels": {"alertname": "RosRobotError", "robot": "alpha"},
    "annotations": {
        "summary": "alpha is in ERROR",
        "message": "/Power/Battery: battery critically low (4 %)",
        "status_page_url": "https://ops.example/?robot=alpha",
        "runbook_url": "docs/runbook.md#rosroboterror",
    },
}
MANY_ERRORS = {
    "labels": {"alertname": "RosRobotError", "robot": "alpha"},
    "annotations": {
        **BATTERY_ERROR["annotations"],
        "message": "/Laser/Laser1: No scans; /Motor/Motor2: Motor fault; /Power/Battery: battery low",
    },
}
ROBOT_DOWN = {
    "labels": {"alertname": "RosRobotDown", "robot": "alpha"},
    "annotations": {"summary": "alpha is down", "status_page_url": "https://ops.example/?robot=alpha"},
}


def render(tmp_path: Any, template: str, data: dict[str, Any]) -> str:
    """`{{ template "<template>" . }}` rendered from the shipped templates by amtool."""
    data_path = tmp_path / "data.json"
    data_path.write_text(json.dumps(data), encoding="utf-8")
    result = run(
        "amtool",
        "template",
        "render",
        f"--template.glob={TEMPLATES}",
        f'--template.text={{{{ template "{template}" . }}}}',
        f"--template.data={data_path}",
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_alertmanager_example_loads_the_shipped_templates() -> None:
    config = yaml.safe_load(ALERTMANAGER_EXAMPLE.read_text(encoding="utf-8"))
    assert [RULES_DIR / path for path in config["templates"]] == [TEMPLATES]


def test_template_titles_a_battery_error_with_its_message(tmp_path: Any) -> None:
    assert render(tmp_path, "overseer.title", notification(BATTERY_ERROR)) == (
        "alpha ERROR — /Power/Battery: battery critically low (4 %)"
    )


def test_template_titles_a_robot_with_many_failing_components_on_one_line(tmp_path: Any) -> None:
    assert render(tmp_path, "overseer.title", notification(MANY_ERRORS)) == (
        "alpha ERROR — /Laser/Laser1: No scans; /Motor/Motor2: Motor fault; /Power/Battery: battery low"
    )


def test_template_text_lists_every_alert_with_its_links(tmp_path: Any) -> None:
    assert render(tmp_path, "overseer.text", notification(BATTERY_ERROR, ROBOT_DOWN)) == (
        "alpha ERROR — /Power/Battery: battery critically low (4 %)\n"
        "  status page: https://ops.example/?robot=alpha\n"
        "  runbook: docs/runbook.md#rosroboterror\n"
        "alpha is down\n"
        "  status page: https://ops.example/?robot=alpha\n"
    )
    assert render(tmp_path, "overseer.title", notification(BATTERY_ERROR, ROBOT_DOWN)) == (
        "alpha: 2 firing, 0 resolved"
    )


def test_template_marks_resolved_alerts_and_falls_back_to_the_summary_without_a_message(
    tmp_path: Any,
) -> None:
    assert render(tmp_path, "overseer.title", notification(BATTERY_ERROR, status="resolved")) == (
        "alpha ERROR — /Power/Battery: battery critically low (4 %) (resolved)"
    )
    quiet = {**BATTERY_ERROR, "annotations": {**BATTERY_ERROR["annotations"], "message": ""}}
    assert render(tmp_path, "overseer.title", notification(quiet)) == "alpha is in ERROR"
