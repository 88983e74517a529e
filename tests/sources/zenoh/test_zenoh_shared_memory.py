"""The exporter's Zenoh session takes no part in Zenoh's shared memory: it maps no one's segments.

Zenoh (1.x) hands a message over 3 kB to a session on the same host through a shared-memory segment of
the sender's (a 16 MB pool a session), and the receiver maps it. A diagnostics array of 50 components is
about 5 kB: an exporter beside a router or robots mapped every sender's pool (about 200 MB at 10,000
robots, 400 B a component of its resident memory), and while samples waited for a busy ingest they held
the sender's buffers, which its own local subscribers share. Here a robot publishing such arrays from
another process, through a real router: the exporter hears it over the link, and maps no segment.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from overseer.config.zenoh import ZenohConfig
from overseer.model import FleetModel
from overseer.sources.zenoh.source import ZenohSource
from testbed.processes import wait_for
from testbed.zenoh import endpoint, running_router

pytestmark = pytest.mark.servers

ROBOT = "bigarrays"

# A robot of its own process (so that its segments are not this process's), 5 kB arrays at 20 Hz.
PUBLISHER = textwrap.dedent(
    """
    import json, sys, time
    import zenoh
    from overseer.codec.cdr import encode_diagnostic_array
    from overseer.messages import DiagnosticArray, DiagnosticStatus
    from overseer.simulator.zenoh_publisher import attachment
    from overseer.sources.zenoh.keys import DIAGNOSTIC_ARRAY_HASH, data_key, publisher_gid, publisher_token

    config = zenoh.Config()  # Zenoh's defaults: shared memory on, as a robot's or a router's may be
    config.insert_json5("mode", json.dumps("client"))
    config.insert_json5("connect/endpoints", json.dumps([sys.argv[1]]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    token = publisher_token(
        0, str(session.zid()), 10, sys.argv[2], "aggregator", "diagnostics_agg", DIAGNOSTIC_ARRAY_HASH
    )
    declared = session.liveliness().declare_token(token)
    gid, key = publisher_gid(token), data_key(0, sys.argv[2], "diagnostics_agg")
    values = tuple((f"key{index}", "x" * 90) for index in range(50))
    status = DiagnosticStatus(0, "/big", "ok", "", values)
    payload = encode_diagnostic_array(DiagnosticArray(0, 0, "", (status,)))
    assert len(payload) > 5000
    number = 0
    while True:
        number += 1
        session.put(key, payload, attachment=attachment(number, time.time_ns(), gid))
        time.sleep(0.05)
    """
)


def zenoh_segments() -> set[str]:
    """The Zenoh shared-memory segments this process maps (other tests' sessions may have some)."""
    maps = Path("/proc/self/maps").read_text(encoding="utf-8").splitlines()
    return {line.split()[-1] for line in maps if line.endswith(".zenoh") and "/dev/shm/" in line}


def test_the_exporter_hears_a_robot_of_its_host_without_mapping_its_shared_memory(tmp_path: Path) -> None:
    before = zenoh_segments()
    model = FleetModel()
    repo = Path(__file__).resolve().parents[3]
    with running_router(tmp_path) as port:
        source = ZenohSource(ZenohConfig(enabled=True, connect=(endpoint(port),)), model)
        source.start()
        robot = subprocess.Popen(
            [sys.executable, "-c", PUBLISHER, endpoint(port), ROBOT],
            env={"PYTHONPATH": f"{repo / 'exporter'}:{repo}", "PATH": "/usr/bin:/bin"},
        )
        try:

            def received() -> int:
                return model.snapshot().message_counts.get(("zenoh", "received"), 0)

            wait_for(lambda: received() >= 40, 60, interval=0.2, message="the robot's arrays heard")
            segments = zenoh_segments() - before
            assert robot.poll() is None, "the robot stopped"
        finally:
            robot.kill()
            robot.wait(10)
            source.stop()
    assert ROBOT in {robot.name for robot in model.snapshot().robots}
    assert segments == set()
