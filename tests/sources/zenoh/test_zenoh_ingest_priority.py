"""Zenoh's samples are ingested on a thread `zenoh.ingest_niceness` nice levels below the exporter's others.

So that on a machine with no core to spare, Zenoh's threads (and, with several workers, the relay's) read
the router's link before the ingest takes its share, and a burst waits in the exporter's queue instead of
being dropped by the router. One exporter's session against a real router, and a worker's relayed source
reading its pipe.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
from pathlib import Path

import pytest

from overseer.codec.cdr import encode_diagnostic_array
from overseer.config.zenoh import DEFAULT_INGEST_NICENESS, ZenohConfig
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.zenoh.keys import DIAGNOSTIC_ARRAY_HASH, data_key, publisher_gid, publisher_token
from overseer.sources.zenoh.relay_items import SAMPLE, TOKEN, Item, encode_batch
from overseer.sources.zenoh.relayed import RelayedZenohSource
from overseer.sources.zenoh.source import ZenohSource
from testbed.processes import wait_for
from testbed.zenoh import client_session, endpoint, running_router

PAYLOAD = encode_diagnostic_array(DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/motor", "ok", "", ()),)))


def own_niceness() -> int:
    """The calling thread's nice value."""
    return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())


@pytest.mark.servers
@pytest.mark.parametrize("niceness", [DEFAULT_INGEST_NICENESS, 0])
def test_the_sessions_samples_are_ingested_below_the_exporters_other_threads(
    tmp_path: Path, niceness: int
) -> None:
    model = FleetModel()
    seen: list[int] = []
    with running_router(tmp_path) as port, client_session(port) as robot:
        config = ZenohConfig(enabled=True, connect=(endpoint(port),), ingest_niceness=niceness)
        source = ZenohSource(config, model)
        ingest = source.ingest.on_sample

        def noted(key: str, attachment: bytes | None, payload: bytes) -> None:
            seen.append(own_niceness())
            ingest(key, attachment, payload)

        source.receiver._on_sample = noted
        source.start()
        try:
            token = publisher_token(
                0, str(robot.zid()), 10, "niced", "aggregator", "diagnostics_agg", DIAGNOSTIC_ARRAY_HASH
            )
            declared = robot.liveliness().declare_token(token)
            gid, key = publisher_gid(token), data_key(0, "niced", "diagnostics_agg")

            def heard() -> bool:
                robot.put(key, PAYLOAD, attachment=attachment(len(seen) + 1, time.time_ns(), gid))
                return [(r.name, len(r.components)) for r in model.snapshot().robots] == [("niced", 1)]

            wait_for(heard, 30, interval=0.2, message="the robot heard")
            declared.undeclare()  # type: ignore[no-untyped-call]
        finally:
            source.stop()
    assert seen and set(seen) == {own_niceness() + niceness}


def test_a_workers_relayed_samples_are_ingested_below_the_relays_threads(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    reader, writer = multiprocessing.Pipe(duplex=False)
    config = ZenohConfig(enabled=True, ingest_niceness=4)
    source = RelayedZenohSource(config, FleetModel(), Shard(), reader)
    items = source.ingest.on_items
    seen: list[int] = []
    heard = threading.Event()

    def noted(batch: list[Item]) -> int:
        seen.append(own_niceness())
        samples = items(batch)
        heard.set()
        return samples

    monkeypatch.setattr(source.ingest, "on_items", noted)
    source.start()
    try:
        token = publisher_token(
            0, "0" * 32, 10, "niced", "aggregator", "diagnostics_agg", DIAGNOSTIC_ARRAY_HASH
        )
        key = data_key(0, "niced", "diagnostics_agg")
        writer.send_bytes(
            encode_batch(
                [(TOKEN, token, True), (SAMPLE, key, attachment(1, 0, publisher_gid(token)), PAYLOAD)]
            )
        )
        assert heard.wait(10)
        wait_for(lambda: source.samples_heard == 1, 10, message="the relayed sample ingested")
    finally:
        source.stop()
        writer.close()
    assert seen == [own_niceness() + 4]
    assert [robot.name for robot in source.ingest._model.snapshot().robots] == ["niced"]
