"""The ROS 2 source holds its wake-up file descriptors only between `start` and `stop`."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from overseer.config.ros2 import Ros2Config
from overseer.model import FleetModel
from overseer.sources.ros2.source import Ros2Source

pytestmark = pytest.mark.servers  # a real ROS 2 node on loopback


def wake_descriptors() -> list[str]:
    """The epoll and eventfd descriptors open in this process, by what they point at."""
    kinds = []
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except FileNotFoundError:  # the descriptor listdir itself used
            continue
        if target in ("anon_inode:[eventpoll]", "anon_inode:[eventfd]"):
            kinds.append(target)
    return sorted(kinds)


def test_a_source_never_started_opens_nothing() -> None:
    before = wake_descriptors()
    source = Ros2Source(Ros2Config(), FleetModel(), "lifecycle_unstarted")
    assert wake_descriptors() == before
    source.stop()  # a source never started stops without a fuss
    assert wake_descriptors() == before


def test_a_stopped_source_has_closed_its_wake_ups(
    tmp_path: Path, dds_domain: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    before = wake_descriptors()
    source = Ros2Source(Ros2Config(domain=dds_domain), FleetModel(), "lifecycle_test")
    source.start()
    assert "anon_inode:[eventpoll]" in wake_descriptors()
    source.stop()
    assert wake_descriptors() == before  # the source's and the middleware's, all closed
