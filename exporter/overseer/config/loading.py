"""The whole configuration: one dataclass tree, read from YAML and flags, validated at start.

Each section is read by its own module; this one knows which sections there are.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml

from overseer.config import (
    alertmanager,
    dds,
    events,
    fleet,
    icinga2,
    ingest,
    inventory,
    maintenance,
    metrics,
    ros1,
    ros2,
    web,
    zenoh,
)
from overseer.config.alertmanager import AlertmanagerConfig
from overseer.config.dds import DdsConfig
from overseer.config.errors import ConfigError
from overseer.config.events import EventsConfig
from overseer.config.fleet import DEFAULT_NAMESPACE_DEPTH
from overseer.config.icinga2 import Icinga2Config
from overseer.config.ingest import IngestConfig
from overseer.config.inventory import InventoryConfig
from overseer.config.maintenance import MaintenanceConfig
from overseer.config.metrics import MetricsConfig
from overseer.config.options import Option, option
from overseer.config.parsers import first_line, reject_unknown, section, string
from overseer.config.ros1 import Ros1Config
from overseer.config.ros2 import Ros2Config
from overseer.config.ros_environment import Origin, apply_ros_defaults
from overseer.config.web import WebConfig
from overseer.config.zenoh import ZenohConfig
from overseer.model import FleetLimits
from overseer.model.shard import Shard

LOG_LEVELS = ("debug", "info", "warning", "error")
LOG_FORMATS = ("text", "json")
_SECTIONS = {
    "web",
    "dds",
    "ros1",
    "zenoh",
    "ros2",
    "fleet",
    "inventory",
    "metrics",
    "ingest",
    "events",
    "maintenance",
}
_TOP_LEVEL_KEYS = {"shard", "log_level", "log_format", "icinga2", "alertmanager"}
TOP_LEVEL_OPTIONS: tuple[Option, ...] = (
    option(
        "shard",
        "0/1",
        "follow only the robots whose name hashes (CRC-32) to shard I of N (several exporters share a fleet)",
        metavar="I/N",
    ),
    option("log_level", "info", "debug, info, warning or error", metavar="LEVEL", flag="--log.level"),
    option(
        "log_format",
        "text",
        "text, or json: one JSON object a line (time, level, logger, message), every recorded event too",
        metavar="FORMAT",
        flag="--log.format",
    ),
)
# Every key of the configuration, in the order `--help` and the reference show them.
ALL_OPTIONS: tuple[Option, ...] = (
    *web.OPTIONS,
    *dds.OPTIONS,
    *ros2.OPTIONS,
    *zenoh.OPTIONS,
    *ros1.OPTIONS,
    *fleet.OPTIONS,
    *inventory.OPTIONS,
    *TOP_LEVEL_OPTIONS,
    *ingest.OPTIONS,
    *metrics.OPTIONS,
    *events.OPTIONS,
    *maintenance.OPTIONS,
    *icinga2.OPTIONS,
    *alertmanager.OPTIONS,
)


@dataclass(frozen=True)
class Config:
    """The whole configuration."""

    web: WebConfig = field(default_factory=WebConfig)
    dds: DdsConfig = field(default_factory=DdsConfig)
    ros1: Ros1Config = field(default_factory=Ros1Config)
    zenoh: ZenohConfig = field(default_factory=ZenohConfig)
    ros2: Ros2Config = field(default_factory=Ros2Config)
    fleet: FleetLimits = field(default_factory=FleetLimits)
    inventory: InventoryConfig = field(default_factory=InventoryConfig)
    metrics: MetricsConfig = field(default_factory=MetricsConfig)
    shard: Shard = field(default_factory=Shard)
    ingest: IngestConfig = field(default_factory=IngestConfig)
    log_level: str = "info"
    events: EventsConfig = field(default_factory=EventsConfig)
    log_format: str = "text"
    icinga2: Icinga2Config | None = None  # push to Icinga 2 when set
    maintenance: MaintenanceConfig = field(default_factory=MaintenanceConfig)
    alertmanager: AlertmanagerConfig | None = None  # silences for maintenance windows when set
    robot_namespace_depth: int = DEFAULT_NAMESPACE_DEPTH  # leading segments of a node's namespace: its robot
    origins: tuple[Origin, ...] = ()  # where the ROS settings came from (flag, file, ROS_* variable)


def load_config(
    path: str | Path | None,
    overrides: dict[str, Any] | None = None,
    environ: Mapping[str, str] | None = None,
) -> Config:
    """Read the YAML file at `path` (None for defaults) and apply dotted-key `overrides` from flags.

    ROS's variables in `environ` (default: this process's environment) give the ROS 2 transports the
    values the flags and the file leave unset, as every ROS 2 node reads them.
    """
    raw: dict[str, Any] = {}
    if path is not None:
        try:
            text = Path(path).read_text(encoding="utf-8")
        except OSError as error:
            raise ConfigError(f"config.file: cannot read {str(path)!r}: {error.strerror}") from None
        try:
            loaded = yaml.safe_load(text)
        except (yaml.YAMLError, ValueError, RecursionError) as error:  # also huge integers, deep nesting
            raise ConfigError(f"config.file: {str(path)!r} is not valid YAML: {first_line(error)}") from None
        if loaded is not None and not isinstance(loaded, dict):
            raise ConfigError(f"config.file: expected a mapping at the top of {str(path)!r}")
        raw = loaded or {}
    for dotted, value in (overrides or {}).items():
        name, _, key = dotted.partition(".")
        target = raw.setdefault(name, {}) if key else raw
        if not isinstance(target, dict):
            raise ConfigError(f"{name}: expected a mapping, got {target!r}")
        target[key or name] = value
    origins = apply_ros_defaults(raw, set(overrides or {}), os.environ if environ is None else environ)
    return replace(config_from_dict(raw), origins=origins)


def config_from_dict(raw: dict[str, Any]) -> Config:
    """Validate a parsed configuration mapping into a `Config`."""
    reject_unknown(raw, "", _SECTIONS | _TOP_LEVEL_KEYS)
    ros2_section = section(raw, "ros2", ros2.KEYS)
    dds_section = section(raw, "dds", dds.KEYS)
    ros2_config = ros2.ros2_config(ros2_section)
    if ros2_config.enabled and "enabled" not in dds_section:
        # The ROS 2 node hears the robots the DDS source would: one of them follows them, unless told.
        dds_section = {**dds_section, "enabled": False}
    fleet_section = section(raw, "fleet", fleet.KEYS)
    config = Config(
        web=web.web_config(section(raw, "web", web.KEYS)),
        dds=dds.dds_config(dds_section),
        ros1=ros1.ros1_config(section(raw, "ros1", ros1.KEYS)),
        zenoh=zenoh.zenoh_config(section(raw, "zenoh", zenoh.KEYS)),
        ros2=ros2_config,
        fleet=fleet.fleet_limits(fleet_section),
        robot_namespace_depth=fleet.robot_namespace_depth(fleet_section),
        inventory=inventory.inventory_config(section(raw, "inventory", inventory.KEYS)),
        metrics=metrics.metrics_config(section(raw, "metrics", metrics.KEYS)),
        ingest=ingest.ingest_config(section(raw, "ingest", ingest.KEYS)),
        events=events.events_config(section(raw, "events", events.KEYS)),
        shard=fleet.parse_shard(raw["shard"]) if "shard" in raw else Shard(),
        log_level=_choice(raw, "log_level", LOG_LEVELS, "info"),
        log_format=_choice(raw, "log_format", LOG_FORMATS, "text"),
        icinga2=None if raw.get("icinga2") is None else icinga2.icinga2_config(raw["icinga2"]),
        maintenance=maintenance.maintenance_config(section(raw, "maintenance", maintenance.KEYS)),
        alertmanager=None
        if raw.get("alertmanager") is None
        else alertmanager.alertmanager_config(section(raw, "alertmanager", alertmanager.KEYS)),
    )
    shared = {domain.id for domain in config.dds.domains} & {config.ros2.domain}
    if config.dds.enabled and config.ros2.enabled and shared:
        raise ConfigError(
            f"ros2.enabled: the DDS source and the ROS 2 node would both follow domain {shared.pop()}'s "
            "robots; turn one off (dds.enabled: false) or give them different domains"
        )
    return config


def _choice(raw: dict[str, Any], key: str, choices: tuple[str, ...], default: str) -> str:
    if key not in raw:
        return default
    value = string(raw[key], key).lower()
    if value not in choices:
        expected = " or ".join(choices) if len(choices) == 2 else ", ".join(choices)
        raise ConfigError(
            f"{key}: expected {'one of ' if len(choices) > 2 else ''}{expected}, got {raw[key]!r}"
        )
    return value


def ros_settings(config: Config) -> str:
    """The ROS settings of the enabled transports and where each came from, for the log at start."""
    values: dict[str, object] = {}
    if config.dds.enabled:
        values["dds.domains"] = ",".join(str(domain.id) for domain in config.dds.domains)
        values["dds.loopback_only"] = str(config.dds.loopback_only).lower()
        values["dds.peers"] = ",".join(str(peer) for peer in config.dds.peers) or "none"
    if config.zenoh.enabled:
        values["zenoh.domain"] = config.zenoh.domain
    if config.ros2.enabled:
        values["ros2.domain"] = config.ros2.domain
    sources = {origin.key: origin.source for origin in config.origins}
    return "; ".join(f"{key} {value} ({sources.get(key, 'default')})" for key, value in values.items())
