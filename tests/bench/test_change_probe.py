"""The change probe: its payload carries the sent time where it writes it, and it times real changes.

End to end through a Zenoh router to a real exporter: every change the probe publishes must be read
back with a latency between zero and its read timeout, read only until it shows (not every poll of
the window: the reads cost the exporter CPU the benchmark counts), and an exporter that never hears
the probe (no router between them) must give no latency at all.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from bench.change_probe import SENT_KEY, SENT_WIDTH, ChangeProbe, probe_payload
from overseer.codec.cdr import WIRE_FORMAT
from overseer.codec.wire import decode_laid_out
from testbed.ports import free_port
from testbed.processes import running_exporter
from testbed.zenoh import endpoint, exporter_args, running_router


def test_the_sent_time_is_written_where_the_decoder_reads_it() -> None:
    payload, offset = probe_payload(50)
    payload[offset : offset + SENT_WIDTH] = b"1764230000.123456"
    statuses = decode_laid_out(WIRE_FORMAT, bytes(payload)).decoded.statuses
    values = [value for status in statuses for value in status.values if value[0] == SENT_KEY]
    assert values == [(SENT_KEY, "1764230000.123456")]
    assert len(statuses) == 50


@pytest.mark.servers
def test_each_change_is_timed_once_it_reaches_the_exporter(tmp_path: Path) -> None:
    with (
        running_router(tmp_path) as port,
        running_exporter(tmp_path, None, *exporter_args(port)) as exporter,
        ChangeProbe(exporter.url, endpoint(port), period=0.5) as probe,
    ):
        time.sleep(6)
    assert probe.published >= 10
    assert len(probe.latencies) >= 5  # the first change read is not timed: it may predate the first read
    assert all(0 < latency < 2 for latency in probe.latencies), probe.latencies
    # Polled every 50 ms throughout, 6 s would be ~120 reads; until each change shows, a few a change
    # (those that failed, before the exporter first heard the probe, left out).
    answered = probe.reads - probe.failed_reads
    assert answered <= 3 * probe.published, (probe.reads, probe.failed_reads, probe.published)


@pytest.mark.servers
def test_an_exporter_that_never_hears_the_probe_times_nothing(tmp_path: Path) -> None:
    with (
        running_router(tmp_path) as port,
        running_exporter(tmp_path, None, *exporter_args(free_port())) as deaf,
        ChangeProbe(deaf.url, endpoint(port), period=0.5) as probe,
    ):
        time.sleep(3)
    assert probe.published >= 5
    assert probe.latencies == [] and probe.failed_reads > 0
    after = next(row for row in probe.rows("deaf") if "after the first look" in row.figure)
    assert after.figure.endswith("p99 (of 0)") and not after.met  # nothing timed: no p99 to hold to 1 s
