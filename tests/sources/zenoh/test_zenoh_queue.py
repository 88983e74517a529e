"""While the ingest is behind, up to `zenoh.queue_length` samples wait for it; beyond, they are counted.

A real router and a Zenoh source in this process, whose ingest the test holds up (as 10,000 robots' first
arrays hold it up for seconds) while a robot publishes a burst of numbered samples of 5 kB. The samples
the queue holds are all read once the ingest goes on; with a queue too short, the rest is dropped: by the
exporter, which counts them dropped, or by the router, and the gaps in the robot's numbers count them lost.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from overseer.codec.cdr import encode_diagnostic_array
from overseer.config.zenoh import ZenohConfig
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetModel
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.zenoh.keys import DIAGNOSTIC_ARRAY_HASH, data_key, publisher_gid, publisher_token
from overseer.sources.zenoh.source import ZenohSource
from testbed.processes import wait_for
from testbed.zenoh import client_session, endpoint, running_router

pytestmark = pytest.mark.servers

BURST = 10_000  # of 5 kB: 50 MB, more than the router and the link hold, and than the old 8,192
BURST_RATE = 2000  # samples a second
VALUES = tuple((f"key{index}", "x" * 90) for index in range(50))
STATUS = DiagnosticStatus(0, "/burst", "ok", "", VALUES)
PAYLOAD = encode_diagnostic_array(DiagnosticArray(0, 0, "", (STATUS,)))


def counts(model: FleetModel) -> tuple[int, int, int]:
    """Samples received, counted lost and counted dropped over Zenoh so far."""
    messages = model.snapshot().message_counts
    received, lost, dropped = (
        messages.get(("zenoh", result), 0) for result in ("received", "lost", "dropped")
    )
    return received, lost, dropped


@pytest.mark.parametrize(("queue_length", "all_kept"), [(BURST + 100, True), (100, False)])
def test_a_burst_waits_for_an_ingest_held_up_by_the_test_as_long_as_the_queue_holds_it(
    tmp_path: Path, queue_length: int, all_kept: bool
) -> None:
    assert len(PAYLOAD) > 5000
    model = FleetModel()
    held_up = threading.Event()
    go_on = threading.Event()
    with running_router(tmp_path) as port, client_session(port) as robot:
        config = ZenohConfig(enabled=True, connect=(endpoint(port),), queue_length=queue_length)
        source = ZenohSource(config, model)
        ingest = source.ingest.on_sample

        def held(key: str, attachment: bytes | None, payload: bytes) -> None:  # held up from the burst on
            if attachment is not None and attachment[:8] != bytes(8):
                held_up.set()
                go_on.wait()
            ingest(key, attachment, payload)

        source.receiver._on_sample = held
        source.start()
        try:
            token = publisher_token(
                0, str(robot.zid()), 10, "bursty", "aggregator", "diagnostics_agg", DIAGNOSTIC_ARRAY_HASH
            )
            declared = robot.liveliness().declare_token(token)  # kept: collected, it would be undeclared
            gid, key = publisher_gid(token), data_key(0, "bursty", "diagnostics_agg")

            def put(number: int) -> None:
                robot.put(key, PAYLOAD, attachment=attachment(number, time.time_ns(), gid))

            def heard() -> bool:
                put(0)  # numbered 0 until heard: the burst counts from there
                return counts(model)[0] > 0

            wait_for(heard, 30, interval=0.2, message="the robot heard")
            started = time.monotonic()
            for number in range(1, BURST + 1):  # at a pace the link and the router keep up with
                put(number)
                time.sleep(max(0.0, started + number / BURST_RATE - time.monotonic()))
            assert held_up.wait(10), "the burst never reached the ingest"
            time.sleep(1)  # the burst's last samples arrive (or are dropped) while the ingest is held up
            go_on.set()

            def settled() -> tuple[int, int, int] | None:
                before = counts(model)
                time.sleep(0.5)
                return before if counts(model) == before else None

            wait_for(settled, 30, message="the samples kept all read")
            put(BURST + 1)  # what the exporter missed of the burst is a gap before this one
            received, lost, dropped = wait_for(settled, 30, message="the sample after the burst read")
            declared.undeclare()  # type: ignore[no-untyped-call]
        finally:
            go_on.set()
            source.stop()
    if all_kept:
        assert (lost, dropped) == (0, 0)
        assert received >= BURST + 2  # the first sample (or more), the whole burst, the one after it
    else:
        assert lost + dropped > 0
        assert received + lost + dropped >= BURST + 2  # every sample of the burst read, or counted
