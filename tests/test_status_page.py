"""The fleet status page, rendered by a real headless Chromium against a live exporter."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

from support.processes import Exporter, running_exporter, running_simulator, wait_for

CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def rendered_dom(url: str, profile: Path) -> str:
    """The page's DOM after its scripts ran, as Chromium dumps it."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    assert chromium, "chromium is installed by make test (Debian package chromium)"
    result = subprocess.run(
        [
            chromium,
            *CHROMIUM_FLAGS,
            f"--user-data-dir={profile}",
            "--virtual-time-budget=5000",
            "--dump-dom",
            url,
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    return result.stdout


def fleet_ready(exporter: Exporter) -> bool:
    robots = exporter.get_json("/api/v1/robots")["robots"]
    return len(robots) == 2 and all(r["up"] and r["components"] == 15 for r in robots)


def test_status_page_shows_each_robot_colored_by_level(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        running_simulator(
            tmp_path,
            dds_domain,
            "--robots=2",
            "--warn=1",
            "--error=0",
            "--event=0:robot2:/Motor/Motor1:ERROR",
        ),
    ):
        wait_for(lambda: fleet_ready(exporter), 30, message="two robots")
        dom = rendered_dom(exporter.url + "/", tmp_path / "profile")
    tiles = dict(re.findall(r'<button class="robot (\w+)"[^>]*data-robot="([^"]+)"', dom))
    assert {robot: state for state, robot in tiles.items()} == {"robot1": "WARN", "robot2": "ERROR"}
    assert 'data-total="ERROR">ERROR 1<' in dom
    assert 'data-total="down">down 0<' in dom


def test_status_page_drills_down_into_a_robot(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=2", "--namespace-prefix=site_a/r"),
    ):
        wait_for(lambda: fleet_ready(exporter), 30, message="two robots")
        dom = rendered_dom(exporter.url + "/#site_a%2Fr2", tmp_path / "profile")
    assert "<h2>site_a/r2: ERROR</h2>" in dom
    rows = re.findall(r'<tr data-component="([^"]+)"><td class="state (\w+)">', dom)
    assert len(rows) == 15
    assert ("/Laser/Laser2", "ERROR") in rows and ("/Camera/Cam2", "WARN") in rows
    assert "Low charge" not in dom and "Charge OK" in dom


def test_status_page_reports_an_unreachable_exporter(tmp_path: Path, dds_domain: int) -> None:
    with running_exporter(tmp_path, dds_domain) as exporter:
        page = exporter.get("/")
    (tmp_path / "index.html").write_bytes(page)
    dom = rendered_dom((tmp_path / "index.html").as_uri(), tmp_path / "profile")
    assert "cannot reach the exporter" in dom
