"""The metric contract's families: name, type, unit, labels and help, in exposition order, in one place.

The renderer writes every header from here, in either format; the tests' prometheus-client oracle builds
its families from here too, so a new metric is one entry below and its samples in the renderer.
"""

from __future__ import annotations

from dataclasses import dataclass

_COMPONENT = ("robot", "component", "hardware_id")


@dataclass(frozen=True)
class MetricFamily:
    """One family of the contract; `name` is the family's (a counter's samples add `_total`)."""

    name: str
    kind: str  # "gauge" or "counter"
    documentation: str
    labels: tuple[str, ...] = ()
    unit: str = ""  # OpenMetrics' `# UNIT`, also the name's last word

    @property
    def sample_name(self) -> str:
        """The name its samples carry."""
        return self.name + "_total" if self.kind == "counter" else self.name


LEVEL = MetricFamily(
    "ros_diagnostics_level", "gauge", "Component level: 0 OK, 1 WARN, 2 ERROR, 3 STALE.", _COMPONENT
)
ROBOT_LEVEL = MetricFamily(
    "ros_diagnostics_robot_level",
    "gauge",
    "Worst component level of the robot (ERROR > WARN > STALE > OK); 3 while the robot is down.",
    ("robot",),
)
ROBOT_UP = MetricFamily(
    "ros_diagnostics_robot_up",
    "gauge",
    "1 while the robot's messages arrive within robot_timeout.",
    ("robot",),
)
LAST_MESSAGE = MetricFamily(
    "ros_diagnostics_robot_last_message_timestamp_seconds",
    "gauge",
    "Unix time of the robot's last diagnostics message.",
    ("robot",),
    unit="seconds",
)
PERIOD = MetricFamily(
    "ros_diagnostics_robot_period_seconds",
    "gauge",
    "How often the robot reports, as learned: its fastest producer's period. Components are STALE after "
    "the larger of stale_after and stale_periods of their producer's period; absent until it is known.",
    ("robot",),
    unit="seconds",
)
ROBOT_INFO = MetricFamily(
    "ros_diagnostics_robot_info",
    "gauge",
    "Every robot followed, with the labels the inventory gives it (site, model, team, ...); always 1. "
    "Join it where a label is needed: * on (robot) group_left (site) ros_diagnostics_robot_info.",
    ("robot",),  # and the robot's inventory labels, which differ from robot to robot
)
ROBOT_COMPONENTS = MetricFamily(
    "ros_diagnostics_robot_components",
    "gauge",
    "The robot's components at each level now (OK, WARN, ERROR, STALE: as ros_diagnostics_level has "
    "them), 0 included: per-robot counts without a pass over every component.",
    ("robot", "level"),
)
ROBOT_LEVEL_CHANGES = MetricFamily(
    "ros_diagnostics_robot_level_changes",
    "counter",
    "Changes of the reported level of the robot's components, all added up (those it no longer has "
    "included): one series a robot, for dashboards; RosRobotFlapping reads the components' own.",
    ("robot",),
)
LEVEL_CHANGES = MetricFamily(
    "ros_diagnostics_level_changes",
    "counter",
    "Changes of a component's reported level (flapping).",
    _COMPONENT,
)
VALUE = MetricFamily(
    "ros_diagnostics_value",
    "gauge",
    "Numeric key-values of a component's status, for the keys the configuration allows.",
    (*_COMPONENT, "key"),
)
STATUS_MESSAGE = MetricFamily(
    "ros_diagnostics_status_message",
    "gauge",
    "A component's status message as a label, cut to metrics.message_label_length, with its level now "
    "(OK, WARN, ERROR, STALE: ros_diagnostics_level's); always 1. "
    "Only for the components metrics.message_labels chooses (default: reported not OK).",
    (*_COMPONENT, "level", "message"),
)
MESSAGES = MetricFamily(
    "overseer_messages",
    "counter",
    "Diagnostics messages by transport and result: received, decode_error, dropped or lost.",
    ("transport", "result"),
)
STATUSES_DROPPED = MetricFamily(
    "overseer_statuses_dropped",
    "counter",
    "Statuses and key-values dropped by the fleet model's caps, by reason.",
    ("reason",),
)
STRINGS_TRUNCATED = MetricFamily(
    "overseer_strings_truncated", "counter", "Names, messages and key-values cut to max_string_length."
)
ROBOTS_FORGOTTEN = MetricFamily(
    "overseer_robots_forgotten",
    "counter",
    "Robots forgotten, by reason: expired (silent for expire_after, not in the inventory), retired (by "
    "overseer robots retire), unlisted (removed from the inventory, never heard) or reattributed (named by "
    "a publisher whose node later named another robot).",
    ("reason",),
)
SOURCE_ERRORS = MetricFamily(
    "overseer_source_errors",
    "counter",
    "Failures to reach robots by transport and reason, such as an unreachable ROS 1 master.",
    ("transport", "reason"),
)
BUILD_INFO = MetricFamily(
    "overseer_build_info",
    "gauge",
    "Overseer's version and status decoder (compiled, or python without one); always 1.",
    ("version", "codec"),
)
WEB_INFO = MetricFamily(
    "overseer_web_info",
    "gauge",
    "The URL users reach this exporter at (web.external_url), for links in alerts; always 1.",
    ("external_url",),
)
MAINTENANCE = MetricFamily(
    "ros_diagnostics_robot_maintenance",
    "gauge",
    "1 while the robot is in a maintenance window, else 0.",
    ("robot",),
)
MAINTENANCE_END = MetricFamily(
    "ros_diagnostics_robot_maintenance_end_timestamp_seconds",
    "gauge",
    "Unix time the maintenance window the robot is in ends.",
    ("robot",),
    unit="seconds",
)
MAINTENANCE_WINDOWS = MetricFamily(
    "overseer_maintenance_windows",
    "gauge",
    "Maintenance windows by state: active, scheduled.",
    ("state",),
)

# Per robot and per component: a model's rendered part holds their lines, in this order.
FLEET_FAMILIES = (
    LEVEL,
    ROBOT_LEVEL,
    ROBOT_UP,
    LAST_MESSAGE,
    PERIOD,
    ROBOT_INFO,
    ROBOT_COMPONENTS,
    ROBOT_LEVEL_CHANGES,
    LEVEL_CHANGES,
    VALUE,
    STATUS_MESSAGE,
)
# The exporter's own, after the fleet's.
EXPORTER_FAMILIES = (
    MESSAGES,
    STATUSES_DROPPED,
    STRINGS_TRUNCATED,
    SOURCE_ERRORS,
    ROBOTS_FORGOTTEN,
    BUILD_INFO,
    WEB_INFO,
)
FORGET_REASONS = ("expired", "retired", "unlisted", "reattributed")
CONTRACT_FAMILIES = FLEET_FAMILIES + EXPORTER_FAMILIES
