"""The Grafana dashboards: valid against Grafana's schema, and every query answered by a live Prometheus.

The live half scrapes an exporter fed by the simulator with the shipped Prometheus config and rules, fills in
the dashboard variables the way Grafana does, and runs every panel target and variable query.
"""

from __future__ import annotations

import json
import re
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
        if any(RAW_LEVEL.fullmatch(target["expr"]) for target in panel["targets"])
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
        """`expr` with variables replaced the way Grafana's Prometheus datasource does."""
        variables = {v["name"]: v for v in load(DASHBOARDS / dashboard_file)["templating"]["list"]}

        def replace(match: re.Match[str]) -> str:
            name = match.group(1) or match.group(2)
            if name in BUILTIN_VARIABLES:
                return BUILTIN_VARIABLES[name]
            chosen = values[name]
            variable = variables[name]
            if not (variable.get("multi") or variable.get("includeAll")):
                return chosen[0]
            escaped = [REGEX_SPECIAL.sub(r"\\\\\g<0>", value) for value in chosen]
            return escaped[0] if len(escaped) == 1 else "(" + "|".join(escaped) + ")"

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
    show maintenance.
    """
    tmp_path = tmp_path_factory.mktemp("dashboards")
    domain = fresh_domain_id()
    all_day = [
        {"robots": "robot1", "from": "00:00", "to": "12:00"},
        {"robots": "robot1", "from": "12:00", "to": "00:00"},
    ]
    config_file = tmp_path / "overseer.yml"
    config_file.write_text(json.dumps({"maintenance": {"windows": all_day}}), encoding="utf-8")
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
        config = shipped_config("prometheus.yml", exporter.url, interval="1s")
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
            # The component counts are recorded once a minute (overseer.components), whatever the interval.
            wait_for(
                lambda: prometheus.query('fleet:ros_diagnostics_level:count{level="ERROR"} > 0'),
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
