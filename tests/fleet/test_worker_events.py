"""A worker's events on their way to the exporter: packed a batch at a time; a bad batch loses no other."""

from __future__ import annotations

import logging
import multiprocessing
import time

import pytest

from overseer.fleet.workers.process import _EventSender
from overseer.levels import Level
from overseer.model.events import Event, PackedRows, unpack_rows


class _Name(str):
    """A robot name of a str subclass, which `marshal` does not pack."""


def level_event(robot: str, at: float) -> Event:
    return Event(at, robot, "level", "/Power/Battery", "", Level.OK, Level.ERROR, "low", (("volts", "11"),))


def test_a_batch_that_cannot_be_packed_is_said_and_the_next_ones_still_reach_the_exporter(
    caplog: pytest.LogCaptureFixture,
) -> None:
    received, sent = multiprocessing.Pipe(duplex=False)
    with caplog.at_level(logging.ERROR):
        sender = _EventSender(sent)
        sender.send([level_event(_Name("robot1"), 1.0)])
        deadline = time.monotonic() + 5
        while "cannot be packed" not in caplog.text and time.monotonic() < deadline:
            time.sleep(0.01)
        sender.send([level_event("robot2", 2.0), level_event("robot3", 3.0)])
        assert received.poll(5)
        packed = received.recv()
    assert isinstance(packed, PackedRows) and packed.events == 2
    assert [row[1] for row in unpack_rows(packed.block)] == ["robot2", "robot3"]
    assert "cannot be packed: 1 events not stored" in caplog.text
