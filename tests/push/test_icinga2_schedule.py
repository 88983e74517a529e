"""Each robot's results repeat at its own phase of the push interval, the same in every run."""

from __future__ import annotations

import subprocess
import sys
from collections import Counter

import pytest

from overseer.push.icinga2_schedule import LEAST_SHARE, next_due, phase

INTERVAL = 60.0


def test_robots_repeat_spread_over_the_interval() -> None:
    robots = [f"site/robot{index}" for index in range(2000)]
    tenths = Counter(int(phase(robot, INTERVAL) / INTERVAL * 10) for robot in robots)
    assert set(tenths) == set(range(10))
    assert all(150 <= count <= 250 for count in tenths.values()), tenths  # 200 each if even


@pytest.mark.parametrize("now", [0.0, 17.3, 1e6 + 0.5])
def test_a_robot_sent_at_its_phase_is_due_an_interval_later(now: float) -> None:
    robot = "site/robot7"
    at_phase = next_due(robot, now, INTERVAL)
    assert next_due(robot, at_phase, INTERVAL) == pytest.approx(at_phase + INTERVAL)
    assert (at_phase - phase(robot, INTERVAL)) % INTERVAL == pytest.approx(0.0, abs=1e-6)


def test_a_robot_sent_between_its_phases_waits_at_least_a_quarter_and_at_most_one_and_a_quarter() -> None:
    robot = "site/robot7"
    for step in range(600):
        now = 1000.0 + step * 0.1  # every moment of an interval
        due = next_due(robot, now, INTERVAL)
        assert now + LEAST_SHARE * INTERVAL <= due < now + (1 + LEAST_SHARE) * INTERVAL


def test_the_phase_comes_from_the_name_alone_not_from_the_process() -> None:
    code = "from overseer.push.icinga2_schedule import phase; print(repr(phase('site/robot7', 60.0)))"
    seen = {
        subprocess.run(
            [sys.executable, "-c", code],
            env={"PYTHONHASHSEED": seed},
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        for seed in ("1", "2")
    }
    assert seen == {repr(phase("site/robot7", INTERVAL))}
