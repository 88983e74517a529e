"""The check's benchmark times only checks that judged their robot: a fast failure would flatter it."""

from __future__ import annotations

import pytest

from bench.bench_check import CHECK, require_judged
from testbed.ports import free_port


def test_a_check_that_cannot_reach_the_exporter_is_not_timed() -> None:
    url = f"http://127.0.0.1:{free_port()}"  # nothing listens there
    with pytest.raises(SystemExit, match=r"did not judge robot1 \(exit 3\): UNKNOWN - "):
        require_judged([str(CHECK), "--url", url, "-r", "robot1"], "robot1")
