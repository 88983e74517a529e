"""The Grafana dashboards: valid against Grafana's schema, and every query answered by a live Prometheus.

What the inventory variables select is checked by promtool on hand-written series, which need no exporter.

The live half scrapes an exporter fed by the simulator with the shipped Prometheus config and rules, fills in
the dashboard variables the way Grafana does, and runs every panel target and variable query.
"""

from __future__ import annotations

import json
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml
from prometheus_client.parser import text_string_to_metric_families

from support.paths import SCHEMAS
from testbed.paths import REPO
from testbed.ports import fresh_domain_id
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for
from testbed.prometheus import Prometheus, load_rules, running_prometheus, selectors, shipped_config

DASHBOARDS = REPO / "dashboards"
DASHBOARD_FILES = sorted(DASHBOARDS.glob("*.json"))
PROVISIONING = DASHBOARDS / "provisioning"
# Grafana's dashboard JSON Schema, kept in the repository (tests/schemas/README.md says where it is from).
SCHEMA = SCHEMAS / "grafana-dashboard.schema.json"
# Keys Grafana adds to an exported dashboard for importing it; they are not part of the dashboard model.
EXPORT_ONLY_KEYS = ("__inputs", "__elements", "__requires")

LEVEL_COLORS = {"OK": "green", "WARN": "yellow", "ERROR": "red", "STALE": "#8e8e8e"}
LEVEL_MAPPING = {str(level): name for level, name in enumerate(LEVEL_COLORS)}
RAW_LEVEL = re.compile(r"ros_diagnostics_(robot_)?level\{[^}]*\}(\s*[<>]=?\s*\d+)*")
# The fleet inventory's labels, a variable each; a panel about robots keeps those the variables select: every
# robot under All (ros_diagnostics_robot_up has none of those labels, and `=~".*"` matches an absent label),
# else the robots whose ros_diagnostics_robot_info has one of the values chosen.
INVENTORY_LABELS = ("site", "model", "team")
INVENTORY_SELECTOR = (
    '{__name__=~"ros_diagnostics_robot_info|ros_diagnostics_robot_up", job="overseer", '
    'site=~"$site", model=~"$model", team=~"$team"}'
)
INVENTORY_FILTER = " and on (job, instance, robot) " + INVENTORY_SELECTOR
# What Grafana puts for its built-in variables; the range covers the data the live Prometheus holds.
BUILTIN_VARIABLES = {"__rate_interval": "1m", "__interval": "15s", "__range": "5m"}
VARIABLE = re.compile(r"\$\{(\w+)(?::\w+)?\}|\$(\w+)")
LABEL_VALUES = re.compile(r"label_values\((.+),\s*(\w+)\)")
REGEX_SPECIAL = re.compile(r"[$^*{}\[\]'+?.()|\\]")
QUERY_WINDOW_SECONDS = 20.0


def load(path: Path) -> dict[str, Any]:
    """A dashboard file as Grafana reads it."""
    dashboard: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return dashboard


def panels(dashboard: dict[str, Any]) -> Iterator[dict[str, Any]]:
    """Every panel, including those inside rows, but not the rows."""
    for panel in dashboard["panels"]:
        if panel["type"] == "row":
            yield from panel["panels"]
        else:
            yield panel


def targets() -> list[tuple[str, str, dict[str, Any]]]:
    """(dashboard file, panel title, target) for every panel target of every dashboard."""
    return [
        (path.name, panel["title"], target)
        for path in DASHBOARD_FILES
        for panel in panels(load(path))
        for target in panel.get("targets", [])
    ]


TARGETS = targets()


def query_variables() -> list[tuple[str, dict[str, Any]]]:
    """(dashboard file, variable) for every query variable of every dashboard."""
    return [
        (path.name, variable)
        for path in DASHBOARD_FILES
        for variable in load(path)["templating"]["list"]
        if variable["type"] == "query"
    ]


def variable_text(variable: dict[str, Any], chosen: list[str], everything: bool) -> str:
    """What Grafana's Prometheus datasource puts for a variable.

    That is its `allValue` when All is selected (`everything`) and it has one, else the values chosen (under
    All, every value), regex-escaped and joined when the variable takes several.
    """
    if everything and "allValue" in variable:
        return str(variable["allValue"])
    if not (variable.get("multi") or variable.get("includeAll")):
        return chosen[0]
    escaped = [REGEX_SPECIAL.sub(r"\\\\\g<0>", value) for value in chosen]
    return escaped[0] if len(escaped) == 1 else "(" + "|".join(escaped) + ")"


def test_there_are_the_two_dashboards() -> None:
    assert [path.name for path in DASHBOARD_FILES] == ["fleet-overview.json", "robot-detail.json"]


@pytest.mark.parametrize("path", DASHBOARD_FILES, ids=lambda path: path.name)
def test_dashboard_validates_against_grafanas_schema(path: Path) -> None:
    schema = json.loads(SCHEMA.read_text(encoding="utf-8"))
    dashboard = {key: value for key, value in load(path).items() if key not in EXPORT_ONLY_KEYS}
    errors = [
        jsonschema.exceptions.best_match(error.context) if error.context else error
        for error in jsonschema.Draft7Validator(schema).iter_errors(dashboard)
    ]
    assert not errors, "\n".join(f"{list(error.absolute_path)}: {error.message[:300]}" for error in errors)


@pytest.mark.parametrize("path", DASHBOARD_FILES, ids=lambda path: path.name)
def test_every_query_uses_the_datasource_variable(path: Path) -> None:
    dashboard = load(path)
    (datasource,) = [v for v in dashboard["templating"]["list"] if v["type"] == "datasource"]
    assert datasource["name"] == "datasource" and datasource["query"] == "prometheus"
    variable_ref = {"type": "prometheus", "uid": "${datasource}"}
    for panel in panels(dashboard):
        assert panel["datasource"] == variable_ref, panel["title"]
        assert all(target["datasource"] == variable_ref for target in panel["targets"]), panel["title"]
    for variable in dashboard["templating"]["list"]:
        if variable["type"] == "query":
            assert variable["datasource"] == variable_ref, variable["name"]


@pytest.mark.parametrize("path", DASHBOARD_FILES, ids=lambda path: path.name)
def test_panels_showing_a_level_map_it_to_its_name_and_color(path: Path) -> None:
    level_panels = [
        panel
        for panel in panels(load(path))
        if any(
            RAW_LEVEL.fullmatch(target["expr"].removesuffix(INVENTORY_FILTER)) for target in panel["targets"]
        )
    ]
    assert level_panels
    for panel in level_panels:
        (mapping,) = panel["fieldConfig"]["defaults"]["mappings"]
        options = mapping["options"]
        assert {value: option["text"] for value, option in options.items()} == LEVEL_MAPPING, panel["title"]
        assert {option["text"]: option["color"] for option in options.values()} == LEVEL_COLORS, panel[
            "title"
        ]


@pytest.mark.parametrize("path", DASHBOARD_FILES, ids=lambda path: path.name)
def test_series_named_after_a_level_have_its_color(path: Path) -> None:
    for panel in panels(load(path)):
        legends = {target["legendFormat"] for target in panel["targets"]}
        if not legends & set(LEVEL_COLORS) and "{{level}}" not in legends:
            continue
        colors = {
            name: override["properties"][0]["value"]["fixedColor"]
            for override in panel["fieldConfig"]["overrides"]
            for name in override["matcher"]["options"]["names"]
        }
        assert colors == LEVEL_COLORS, panel["title"]


@pytest.mark.parametrize("path", DASHBOARD_FILES, ids=lambda path: path.name)
def test_the_inventory_labels_are_variables_whose_all_matches_robots_without_them(path: Path) -> None:
    variables = {variable["name"]: variable for variable in load(path)["templating"]["list"]}
    for label in INVENTORY_LABELS:
        variable = variables[label]
        assert variable["query"] == f'label_values(ros_diagnostics_robot_info{{job="overseer"}}, {label})'
        assert variable["multi"] and variable["includeAll"], label
        # Grafana's own All is the list of values found, which misses the robots without the label.
        assert variable["allValue"] == ".*", label
        assert variable["current"] == {"text": ["All"], "value": ["$__all"]}, label


def test_every_fleet_panel_about_robots_shows_the_robots_the_inventory_variables_select() -> None:
    for panel in panels(load(DASHBOARDS / "fleet-overview.json")):
        for target in panel["targets"]:
            read = {selector.metric for selector in selectors(target["expr"])}
            if read <= {"overseer_messages_total", "overseer_statuses_dropped_total"}:
                continue  # the exporter's own counters: no robot to filter
            assert INVENTORY_FILTER in target["expr"], f"{panel['title']}: {target['expr']}"


def test_the_robot_detail_offers_the_robots_the_inventory_variables_select() -> None:
    variables = {v["name"]: v for v in load(DASHBOARDS / "robot-detail.json")["templating"]["list"]}
    assert variables["robot"]["query"] == f"label_values({INVENTORY_SELECTOR}, robot)"
    names = list(variables)
    assert all(names.index(label) < names.index("robot") for label in INVENTORY_LABELS)


def test_links_to_the_robot_detail_keep_the_inventory_variables() -> None:
    text = (DASHBOARDS / "fleet-overview.json").read_text(encoding="utf-8")
    links = re.findall(r'"url": "(/d/overseer-robot/[^"]*)"', text)
    assert links
    for link in links:
        assert all(f"${{{label}:queryparam}}" in link for label in INVENTORY_LABELS), link


# A fleet for promtool: robots listed with labels, one listed without, one of an exporter with no inventory.
FILTER_FLEET = {
    "a1": ({"site": "site_a", "model": "tb4", "team": "logistics"}, 2),
    "a2": ({"site": "site_a", "model": "tb3", "team": "inspection"}, 0),
    "b1": ({"site": "site_b", "model": "tb4", "team": "logistics"}, 2),
    "unlabelled": ({}, 2),
    "old": (None, 1),
}


def filter_fleet_series() -> list[dict[str, str]]:
    """FILTER_FLEET's input series: each robot's level, up, info (unless None), one component's counts."""
    series = []
    for robot, (labels, level) in FILTER_FLEET.items():
        own = f'job="overseer", instance="overseer:9849", robot="{robot}"'
        series += [
            {"series": f"ros_diagnostics_robot_level{{{own}}}", "values": f"{level}x8"},
            {"series": f"ros_diagnostics_robot_up{{{own}}}", "values": "1x8"},
        ]
        series += [
            {
                "series": f'ros_diagnostics_robot_components{{{own}, level="{name}"}}',
                "values": f"{int(value == level)}x8",
            }
            for value, name in enumerate(LEVEL_NAMES)
        ]
        if labels is not None:
            inventory = "".join(f', {name}="{value}"' for name, value in labels.items())
            series.append({"series": f"ros_diagnostics_robot_info{{{own}{inventory}}}", "values": "1x8"})
    return series


LEVEL_NAMES = ("OK", "WARN", "ERROR", "STALE")


# (site, model, team) chosen, None for All → the robots the fleet overview shows.
SELECTIONS = [
    ((None, None, None), {"a1", "a2", "b1", "unlabelled", "old"}),
    ((["site_a"], None, None), {"a1", "a2"}),
    ((["site_a", "site_b"], None, None), {"a1", "a2", "b1"}),
    ((None, ["tb4"], ["logistics"]), {"a1", "b1"}),
    ((["site_b"], None, ["inspection"]), set()),
]


@pytest.mark.parametrize(
    ("chosen", "shown"), SELECTIONS, ids=["all", "site_a", "two_sites", "tb4_logistics", "nobody"]
)
def test_promtool_shows_the_robots_and_counts_of_the_sites_models_and_teams_chosen(
    tmp_path: Path, chosen: tuple[list[str] | None, ...], shown: set[str]
) -> None:
    variables = {v["name"]: v for v in load(DASHBOARDS / "fleet-overview.json")["templating"]["list"]}
    choice = dict(zip(INVENTORY_LABELS, chosen, strict=True))

    def replace(match: re.Match[str]) -> str:
        name = match.group(1) or match.group(2)
        values = choice[name]
        if values is None:  # All: every value label_values() finds, as Grafana has them
            found = {labels[name] for labels, _ in FILTER_FLEET.values() if labels and name in labels}
            return variable_text(variables[name], sorted(found), everything=True)
        return variable_text(variables[name], values, everything=False)

    def expr(panel_title: str, ref: str) -> str:
        (target,) = [
            t
            for file, title, t in TARGETS
            if file == "fleet-overview.json" and title == panel_title and t["refId"] == ref
        ]
        return VARIABLE.sub(replace, target["expr"])

    in_error = [robot for robot in shown if FILTER_FLEET[robot][1] == 2]
    own = 'job="overseer", instance="overseer:9849"'
    test = {
        "rule_files": [str(REPO / "alert_rules" / "overseer.rules.yml")],
        "evaluation_interval": "15s",
        "tests": [
            {
                "interval": "15s",
                "input_series": filter_fleet_series(),
                "promql_expr_test": [
                    {
                        "expr": expr("Robots", "A"),
                        "eval_time": "1m",
                        "exp_samples": [
                            {
                                "labels": f'ros_diagnostics_robot_level{{{own}, robot="{robot}"}}',
                                "value": FILTER_FLEET[robot][1],
                            }
                            for robot in sorted(shown)
                        ],
                    },
                    {
                        "expr": expr("Robots by level", "A"),
                        "eval_time": "1m",
                        "exp_samples": [{"labels": "{}", "value": len(in_error)}],
                    },
                    {
                        "expr": expr("Components by level", "A"),
                        "eval_time": "1m",
                        "exp_samples": [{"labels": "{}", "value": len(in_error)}],
                    },
                ],
            }
        ],
    }
    path = tmp_path / "dashboard.test.yml"
    path.write_text(yaml.safe_dump(test), encoding="utf-8")
    result = subprocess.run(
        ["promtool", "test", "rules", str(path)], capture_output=True, text=True, timeout=60, check=False
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_provisioning_makes_a_prometheus_the_default_datasource() -> None:
    (datasource,) = yaml.safe_load((PROVISIONING / "datasources" / "overseer.yml").read_text())["datasources"]
    assert datasource["type"] == "prometheus" and datasource["isDefault"] is True


# --- live: every query against a Prometheus that scrapes the exporter fed by the simulator ---


class LiveFleet:
    """A simulated fleet, its exporter, and a Prometheus that scrapes it with the shipped config and rules."""

    def __init__(
        self, exporter: Exporter, prometheus: Prometheus, recording_rules: dict[str, list[str]]
    ) -> None:
        """Hold the servers; `recording_rules` maps recorded names to the expressions recording them."""
        self.exporter = exporter
        self.prometheus = prometheus
        self.recording_rules = recording_rules
        self.exported = {
            sample.name
            for family in text_string_to_metric_families(exporter.get("/metrics").decode())
            for sample in family.samples
        }

    def variable_values(self, dashboard_file: str) -> dict[str, list[str]]:
        """Each variable's values as Grafana resolves them, in templating order; the first is the default."""
        values: dict[str, list[str]] = {}
        for variable in load(DASHBOARDS / dashboard_file)["templating"]["list"]:
            if variable["type"] != "query":
                continue
            parsed = LABEL_VALUES.fullmatch(self.substitute(variable["query"], dashboard_file, values))
            assert parsed, f"{variable['name']}: not a label_values() query"
            selector, label = parsed.groups()
            found = {series[label] for series in self.prometheus.series(selector) if label in series}
            values[variable["name"]] = sorted(found, key=natural_order)
        return values

    def substitute(self, expr: str, dashboard_file: str, values: dict[str, list[str]]) -> str:
        """`expr` with variables at their defaults, replaced the way Grafana's Prometheus datasource does.

        A variable that includes All is at All; any other at its first value.
        """
        variables = {v["name"]: v for v in load(DASHBOARDS / dashboard_file)["templating"]["list"]}

        def replace(match: re.Match[str]) -> str:
            name = match.group(1) or match.group(2)
            if name in BUILTIN_VARIABLES:
                return BUILTIN_VARIABLES[name]
            variable = variables[name]
            return variable_text(variable, values[name], bool(variable.get("includeAll")))

        return VARIABLE.sub(replace, expr)

    def unknown_metrics(self, expr: str) -> set[str]:
        """Metrics `expr` selects that neither the exporter nor a recording rule over its metrics provides."""
        unknown = set()
        for selector in selectors(expr):
            if selector.metric in self.recording_rules:
                for recorded in self.recording_rules[selector.metric]:
                    unknown |= self.unknown_metrics(recorded)
            elif selector.metric not in self.exported:
                unknown.add(selector.metric)
        return unknown


def natural_order(text: str) -> list[Any]:
    """Sort key that puts robot2 before robot10, as Grafana's natural sort does."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text)]


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveFleet]:
    """Three simulated robots with one ERROR and one WARN component each; robot1 has a stale one too.

    robot1 is in maintenance all day, by two recurring windows of the configuration, for the panels that
    show maintenance. The inventory gives robot1 and robot2 a site, a model and a team, and leaves robot3
    out, for the dashboards' variables and the panels filtered by them.
    """
    tmp_path = tmp_path_factory.mktemp("dashboards")
    domain = fresh_domain_id()
    all_day = [
        {"robots": "robot1", "from": "00:00", "to": "12:00"},
        {"robots": "robot1", "from": "12:00", "to": "00:00"},
    ]
    inventory = tmp_path / "inventory.yml"
    inventory.write_text(
        "robots:\n"
        "  robot1: {labels: {site: site_a, model: tb4, team: logistics}}\n"
        "  robot2: {labels: {site: site_b, model: tb4, team: inspection}}\n",
        encoding="utf-8",
    )
    config_file = tmp_path / "overseer.yml"
    config_file.write_text(
        json.dumps({"maintenance": {"windows": all_day}, "inventory": {"file": str(inventory)}}),
        encoding="utf-8",
    )
    # A component that goes stale for the stale panels, and level changes for the level-change graphs.
    events = ["--event=2:robot1:/Temp/Sensor1:silence", "--event=3:robot1:/Motor/Motor1:WARN"]
    events += ["--event=5:robot1:/Motor/Motor1:OK"]
    with (
        running_exporter(
            tmp_path,
            domain,
            f"--config.file={config_file}",
            "--fleet.stale-after=2s",
            "--fleet.robot-timeout=3s",
        ) as exporter,
        running_simulator(tmp_path, domain, "--robots=3", "--components=10", *events),
    ):
        config = shipped_config("prometheus.yml", [exporter.url], interval="1s")
        recording_rules: dict[str, list[str]] = {}
        for rule in (rule for path in config["rule_files"] for rule in load_rules(Path(path))):
            if "record" in rule:
                recording_rules.setdefault(rule["record"], []).append(rule["expr"])
        with running_prometheus(tmp_path, config) as prometheus:
            wait_for(
                lambda: prometheus.query(
                    'ros_diagnostics_level{robot="robot1", component="/Temp/Sensor1"} == 3'
                ),
                timeout=60,
                message="robot1's /Temp/Sensor1 stale in Prometheus",
            )
            wait_for(
                lambda: prometheus.query("count_over_time(fleet:ros_diagnostics_robot_up:sum[1m]) > 10"),
                timeout=60,
                message="10s of recorded fleet counts",
            )
            # The fleet's component counts are recorded once a minute (overseer.components).
            wait_for(
                lambda: prometheus.query('fleet:ros_diagnostics_robot_components:sum{level="ERROR"} > 0'),
                timeout=90,
                message="recorded component counts",
            )
            yield LiveFleet(exporter, prometheus, recording_rules)


@pytest.mark.servers
@pytest.mark.parametrize(
    ("dashboard_file", "variable"), query_variables(), ids=lambda x: x if isinstance(x, str) else x["name"]
)
def test_variable_query_returns_values(
    live: LiveFleet, dashboard_file: str, variable: dict[str, Any]
) -> None:
    assert live.variable_values(dashboard_file)[variable["name"]], f"{variable['query']} returned nothing"


@pytest.mark.servers
@pytest.mark.parametrize(
    ("dashboard_file", "panel_title", "target"),
    TARGETS,
    ids=[f"{file}:{title}:{target['refId']}" for file, title, target in TARGETS],
)
def test_panel_target_selects_exported_metrics_and_returns_data(
    live: LiveFleet, dashboard_file: str, panel_title: str, target: dict[str, Any]
) -> None:
    expr = live.substitute(target["expr"], dashboard_file, live.variable_values(dashboard_file))
    assert live.unknown_metrics(expr) == set(), f"{expr} selects metrics nobody exports"
    if target["instant"]:
        assert live.prometheus.query(expr), f"{expr} returned nothing"
    else:
        series = live.prometheus.query_range(expr, QUERY_WINDOW_SECONDS)
        assert any(one["values"] for one in series), f"{expr} returned nothing over {QUERY_WINDOW_SECONDS}s"
