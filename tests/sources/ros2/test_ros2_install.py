"""Without the ros2 extra, what needs rclpy says so in one line and stops; nothing else needs it."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

from testbed.processes import overseer_command


def run_without_rclpy(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """`overseer ARGS` with an rclpy that cannot be imported in front of the real one."""
    shadow = tmp_path / "shadow"
    shadow.mkdir()
    (shadow / "rclpy.py").write_text("raise ImportError('no module named rclpy (simulated)')\n")
    env = {**os.environ, "PYTHONPATH": f"{shadow}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    return subprocess.run(
        [*overseer_command(), *args], capture_output=True, text=True, timeout=60, env=env, cwd=tmp_path
    )


def test_run_with_ros2_without_rclpy_is_one_configuration_error(tmp_path: Path) -> None:
    done = run_without_rclpy(
        tmp_path, "run", "--ros2", "--ingest.workers=1", "--web.listen-address=127.0.0.1:0"
    )
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "overseer run: configuration error: ros2.enabled (--ros2) needs rclpy and diagnostic_msgs: "
        "install them with pip install 'overseer[ros2]', or run on a ROS 2 host's Python "
        "(no module named rclpy (simulated))"
    ]


def test_simulating_over_ros2_without_rclpy_is_one_configuration_error(tmp_path: Path) -> None:
    done = run_without_rclpy(tmp_path, "simulate", "--transport=ros2", "--duration=1")
    assert done.returncode == 2
    assert "--transport ros2 needs rclpy and diagnostic_msgs" in done.stderr
