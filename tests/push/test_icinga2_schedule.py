"""Each robot's results repeat at its own moment of the push interval, the same after a restart."""

from __future__ import annotations

import os
import subprocess
import sys
from collections import Counter

import pytest

from overseer.push.icinga2_schedule import next_due, phase

INTERVAL = 60.0


def test_robots_repeat_spread_over_the_interval() -> None:
    robots = [f"site/robot{index}" for index in range(2000)]
    tenths = Counter(int(phase(robot, INTERVAL) / INTERVAL * 10) for robot in robots)
    assert set(tenths) == set(range(10))
    assert all(150 <= count <= 250 for count in tenths.values()), tenths  # 200 each if even


@pytest.mark.parametrize("now", [0.0, 17.3, 1e6 + 0.5])
def test_a_robot_sent_at_its_moment_is_due_an_interval_later(now: float) -> None:
    robot = "site/robot7"
    at_moment = next_due(robot, now, INTERVAL)
    assert next_due(robot, at_moment, INTERVAL) == pytest.approx(at_moment + INTERVAL)
    assert next_due(robot, at_moment + 0.3, INTERVAL) == pytest.approx(at_moment + INTERVAL)  # sent late
    assert (at_moment - phase(robot, INTERVAL)) % INTERVAL == pytest.approx(0.0, abs=1e-6)


def test_a_robot_sent_between_its_moments_is_due_at_the_next_one_within_an_interval() -> None:
    robot = "site/robot7"
    dues = set()
    for step in range(600):
        now = 1000.0 + step * 0.1  # every moment of an interval
        due = next_due(robot, now, INTERVAL)
        assert now < due <= now + INTERVAL
        dues.add(round(due, 6))
    assert len(dues) == 2  # the moment in this interval, then the one in the next


def test_the_moment_comes_from_the_name_alone_not_from_the_process() -> None:
    code = "from overseer.push.icinga2_schedule import phase; print(repr(phase('site/robot7', 60.0)))"
    seen = {
        subprocess.run(
            [sys.executable, "-c", code],
            env={**os.environ, "PYTHONHASHSEED": seed},
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        for seed in ("1", "2")
    }
    assert seen == {repr(phase("site/robot7", INTERVAL))}
