"""An ingest worker's process ends when its exporter leaves, whatever the interpreter's shutdown would do."""

from __future__ import annotations

import atexit
import threading
from dataclasses import replace
from multiprocessing.connection import Connection, Pipe

from overseer.config import Config
from overseer.config.dds import DdsConfig
from overseer.config.events import EventsConfig
from overseer.fleet.workers.answers import receive_answer
from overseer.fleet.workers.launch import start_child
from overseer.fleet.workers.process import READY, run_worker

EXIT_TIMEOUT_SECONDS = 15.0


def worker_whose_shutdown_hangs(config: Config, requests: Connection, events: Connection) -> None:
    """A worker process in which the interpreter's shutdown never ends.

    As it does when a DDS entity's finalizer waits for a listener thread that waits for the interpreter.
    """
    atexit.register(threading.Event().wait)
    run_worker(config, 0, 1, requests, events)


def test_a_worker_ends_when_its_exporter_closes_the_pipe_even_if_the_interpreter_would_hang() -> None:
    config = replace(Config(), dds=replace(DdsConfig(), enabled=False), events=EventsConfig(enabled=False))
    requests, child_requests = Pipe()
    events_read, child_events = Pipe(duplex=False)
    process = start_child(worker_whose_shutdown_hangs, (config, child_requests, child_events))  # as the pool
    child_requests.close()
    child_events.close()
    try:
        assert requests.poll(EXIT_TIMEOUT_SECONDS), "the worker never said it was ready"
        assert receive_answer(requests, EXIT_TIMEOUT_SECONDS) == (READY, None)
        requests.close()  # the exporter leaves
        process.join(EXIT_TIMEOUT_SECONDS)
        assert process.exitcode == 0, "the worker outlived its exporter"
    finally:
        events_read.close()
        if process.is_alive():
            process.kill()
            process.join()
