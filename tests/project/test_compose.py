"""deploy/docker-compose.yml: what it mounts exists, and the configs it runs pass promtool and amtool.

Docker is not needed: the test reads the compose file, maps container paths back to the repository through
its bind mounts, and checks the files there, including paths the configs name relative to themselves.
"""

from __future__ import annotations

import posixpath
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml

from testbed.paths import REPO

DEPLOY = REPO / "deploy"
COMPOSE = yaml.safe_load((DEPLOY / "docker-compose.yml").read_text(encoding="utf-8"))
SERVICES: dict[str, Any] = COMPOSE["services"]


def bind_mounts(service: str) -> dict[str, Path]:
    """The service's bind mounts: container path -> host path (named volumes left out)."""
    mounts = {}
    for volume in SERVICES[service].get("volumes", []):
        source, target = volume.split(":")[:2]
        if source.startswith((".", "/")):
            mounts[target] = (DEPLOY / source).resolve()
    return mounts


def host_path(service: str, container_path: str) -> Path:
    """Where a path inside the service's container comes from in the repository."""
    container_path = posixpath.normpath(container_path)
    for target, source in sorted(bind_mounts(service).items(), key=lambda mount: -len(mount[0])):
        if container_path == target or container_path.startswith(target + "/"):
            return source / posixpath.relpath(container_path, target)
    raise AssertionError(f"{service}: {container_path} is not on a bind mount")


def flag(service: str, name: str) -> str:
    """The value of `--name=value` in the service's command."""
    prefix = f"--{name}="
    (value,) = [arg.removeprefix(prefix) for arg in SERVICES[service]["command"] if arg.startswith(prefix)]
    return str(value)


def run(*args: str) -> subprocess.CompletedProcess[str]:
    """Run a command to completion, capturing its output."""
    return subprocess.run(args, capture_output=True, text=True, timeout=60, check=False)


def test_the_stack_has_exporter_simulator_prometheus_alertmanager_and_grafana() -> None:
    assert set(SERVICES) == {"exporter", "simulator", "prometheus", "alertmanager", "grafana"}


@pytest.mark.parametrize("service", sorted(SERVICES))
def test_every_bind_mount_exists(service: str) -> None:
    for target, source in bind_mounts(service).items():
        assert source.exists(), f"{service}: {source} (mounted at {target}) does not exist"


def test_the_exporter_image_builds_from_the_repository_dockerfile() -> None:
    build = SERVICES["exporter"]["build"]
    assert (DEPLOY / build["context"] / build["dockerfile"]).resolve() == REPO / "Dockerfile"
    assert (REPO / "Dockerfile").exists()
    assert SERVICES["simulator"]["image"] == SERVICES["exporter"]["image"]


def test_prometheus_config_passes_promtool_and_its_rule_files_are_mounted() -> None:
    config_path = flag("prometheus", "config.file")
    result = run("promtool", "check", "config", str(host_path("prometheus", config_path)))
    assert result.returncode == 0, result.stdout + result.stderr
    config = yaml.safe_load(host_path("prometheus", config_path).read_text(encoding="utf-8"))
    for rule_file in config["rule_files"]:
        in_container = posixpath.join(posixpath.dirname(config_path), rule_file)
        assert host_path("prometheus", in_container).is_file(), rule_file


def test_alertmanager_config_passes_amtool() -> None:
    result = run(
        "amtool", "check-config", str(host_path("alertmanager", flag("alertmanager", "config.file")))
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_grafana_provisioning_finds_the_datasource_and_every_dashboard() -> None:
    provisioning = "/etc/grafana/provisioning"
    (datasources,) = host_path("grafana", f"{provisioning}/datasources").glob("*.yml")
    (dashboards,) = host_path("grafana", f"{provisioning}/dashboards").glob("*.yml")
    assert yaml.safe_load(datasources.read_text(encoding="utf-8"))["datasources"]
    (provider,) = yaml.safe_load(dashboards.read_text(encoding="utf-8"))["providers"]
    found = {path.name for path in host_path("grafana", provider["options"]["path"]).glob("*.json")}
    assert found == {path.name for path in (REPO / "dashboards").glob("*.json")} != set()
    home = SERVICES["grafana"]["environment"]["GF_DASHBOARDS_DEFAULT_HOME_DASHBOARD_PATH"]
    assert host_path("grafana", home).is_file()


def test_the_services_find_each_other_on_the_ports_they_listen_on() -> None:
    assert all(service["network_mode"] == "host" for service in SERVICES.values())
    config = yaml.safe_load(
        host_path("prometheus", flag("prometheus", "config.file")).read_text(encoding="utf-8")
    )
    (overseer,) = [job for job in config["scrape_configs"] if job["job_name"] == "overseer"]
    ((exporter_target,),) = [static["targets"] for static in overseer["static_configs"]]
    assert exporter_target == "localhost" + flag("exporter", "web.listen-address")
    ((alertmanager_target,),) = [
        static["targets"]
        for manager in config["alerting"]["alertmanagers"]
        for static in manager["static_configs"]
    ]
    assert alertmanager_target == "localhost" + flag("alertmanager", "web.listen-address")
    provisioning = host_path("grafana", "/etc/grafana/provisioning/datasources")
    (datasource,) = yaml.safe_load(next(provisioning.glob("*.yml")).read_text(encoding="utf-8"))[
        "datasources"
    ]
    assert datasource["url"] == "http://localhost" + flag("prometheus", "web.listen-address")


def test_the_simulated_fleet_is_on_the_exporters_dds_domain_over_loopback() -> None:
    exporter, simulator = SERVICES["exporter"]["command"], SERVICES["simulator"]["command"]
    assert flag("exporter", "dds.domain") == flag("simulator", "domain")
    assert "--dds.loopback-only" in exporter and "--dds.loopback-only" in simulator
