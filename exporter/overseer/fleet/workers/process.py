"""One ingest worker: its share of the robots, its own fleet model, and answers to the exporter's requests.

The exporter talks to a worker over two pipes: requests and answers on one, the worker's events (for the
event history) on the other. The worker ends when the exporter closes the request pipe, or dies with it.
"""

from __future__ import annotations

import logging
import os
import queue
import signal
import threading
from dataclasses import replace
from multiprocessing.connection import Connection
from typing import Any, NoReturn

from overseer.config import Config
from overseer.fleet.documents import ComponentQuery
from overseer.fleet.interface import FleetStart
from overseer.fleet.local import LocalFleet
from overseer.fleet.workers.answers import send_answer
from overseer.fleet.workers.merge import portable_robots
from overseer.fleet.workers.shared_counts import SharedCounts
from overseer.garbage_collection import collect_in_large_batches
from overseer.heap_trim import shape_heap, trim_heap_every
from overseer.log_format import configure_logging
from overseer.model.events import Event, event_rows, pack_rows
from overseer.model.robot_cap import SharedRobotCap
from overseer.sources.zenoh.relay_items import RelayedFeed

log = logging.getLogger(__name__)

READY = "ready"
FAILED = "failed"


def worker_config(config: Config, worker: int, workers: int) -> Config:
    """The configuration worker `worker` of `workers` runs with: its robots (the cap is the fleet's)."""
    return replace(
        config,
        shard=config.shard.for_worker(worker, workers),
        icinga2=None,  # the exporter pushes for the whole fleet
    )


def answer(fleet: LocalFleet, kind: str, argument: Any) -> Any:
    """The answer of a worker's fleet to one request from the exporter (one of `PooledFleet`'s)."""
    if kind == "part":
        [part] = fleet.exposition_parts()
        return part
    if kind == "prepare":
        fleet.prepare_exposition()
        return None
    if kind == "robots":
        return fleet.robots_document(argument)
    if kind == "names":
        return fleet.robot_names()
    if kind == "robot":
        return fleet.robot_document(argument)
    if kind == "components":
        assert isinstance(argument, ComponentQuery)
        return fleet.components_document(argument)
    if kind == "digests":
        return fleet.robot_digests()
    if kind == "snapshot_of":
        snapshot = fleet.robots_snapshot(argument)
        return replace(snapshot, robots=tuple(portable_robots(snapshot)))
    if kind == "inventory":
        fleet.set_inventory(argument)
        return None
    if kind == "retire":
        return fleet.retire(argument)
    if kind == "heard":
        return fleet.heard(bool(argument))
    raise ValueError(f"unknown request {kind!r}")


def run_worker(
    config: Config,
    worker: int,
    workers: int,
    requests: Connection,
    events: Connection,
    start: FleetStart | None = None,
    relayed: dict[str, RelayedFeed] | None = None,
    robot_counts: SharedCounts | None = None,
) -> NoReturn:
    """The worker process: start following its robots, then answer requests until the exporter leaves.

    `start` is what it follows before it hears anything (its share of it: the robots it owns);
    `relayed` the pipe (and ring) its robots' samples come down from the exporter's DDS participant or
    Zenoh session, by transport;
    `robot_counts` every worker's robots, one slot each, against `fleet.max_robots`. Once its
    fleet has stopped, the process ends at once, without the interpreter's shutdown: that shutdown can
    hang (a DDS entity's finalizer waits for a listener thread that waits for the interpreter), and a
    worker left behind by a dead exporter would hold its robots' readers for good.
    """
    collect_in_large_batches()
    shape_heap()
    trim_heap_every()
    status = 1
    try:
        status = _serve(config, worker, workers, requests, events, start, relayed, robot_counts)
    except BaseException:  # whatever ends it (the exporter gone, a signal): `_exit` would say nothing
        log.exception("ingest worker %d ended", worker)
    finally:
        logging.shutdown()
        os._exit(status)


def _serve(
    config: Config,
    worker: int,
    workers: int,
    requests: Connection,
    events: Connection,
    start: FleetStart | None,
    relayed: dict[str, RelayedFeed] | None,
    robot_counts: SharedCounts | None,
) -> int:
    """Follow this worker's robots and answer requests until the exporter leaves; the exit status."""
    # Ctrl-C reaches the whole process group, and systemd's stop the whole cgroup: the exporter decides,
    # and a worker ends when the exporter closes its pipe (or dies).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    configure_logging(config.log_level, config.log_format, worker)
    config = worker_config(config, worker, workers)
    try:
        sink = _EventSender(events).send if config.events.enabled else None
        cap = (
            None
            if robot_counts is None
            else SharedRobotCap(config.fleet.max_robots, robot_counts.slots, worker)
        )
        fleet = LocalFleet.build(config, sink, start, relayed, cap)
        fleet.start()
    except Exception as error:  # told to the exporter, which fails its start with it
        log.exception("ingest worker %d failed to start", worker)
        send_answer(requests, (FAILED, f"{type(error).__name__}: {error}"))
        return 1
    send_answer(requests, (READY, None))
    while True:
        try:
            kind, argument = requests.recv()
        except (EOFError, OSError):
            break  # the exporter is gone or stopping
        try:
            reply: tuple[str, Any] = ("ok", answer(fleet, kind, argument))
        except Exception as error:
            log.exception("ingest worker %d failed to answer %s", worker, kind)
            reply = ("error", f"{type(error).__name__}: {error}")
        try:
            send_answer(requests, reply)
        except (BrokenPipeError, OSError):
            break
    fleet.stop()
    return 0


class _EventSender:
    """Sends the detector's events to the exporter from a thread of its own, so ingest never waits on it.

    They go as the store's rows, packed: the exporter only queues and writes them (a fleet first heard
    gives 50 a robot).
    """

    def __init__(self, connection: Connection) -> None:
        self._connection = connection
        self._queue: queue.SimpleQueue[list[Event]] = queue.SimpleQueue()
        threading.Thread(target=self._send_loop, name="event-sender", daemon=True).start()

    def send(self, events: list[Event]) -> None:
        if events:
            self._queue.put(events)

    def _send_loop(self) -> None:
        while True:
            batch = self._queue.get()
            while not self._queue.empty() and len(batch) < 10_000:
                batch = batch + self._queue.get()
            try:
                packed = pack_rows(event_rows(batch))
            except ValueError:  # a value of a type not packed: a bug, said, and the next batches go on
                log.exception(
                    "ingest events of a type that cannot be packed: %d events not stored", len(batch)
                )
                continue
            try:
                self._connection.send(packed)
            except (BrokenPipeError, OSError):
                return  # the exporter is gone; the request loop ends the worker
