"""The ingest workers of one exporter: started, asked, watched, and restarted when one dies.

Workers are fresh interpreters (`launch.start_child`), not forks: the exporter runs threads, and a forked
copy of a thread holding a lock (logging's, Cyclone's) would wait on it forever.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, Pipe
from typing import Any, NamedTuple, Protocol

from overseer.config import Config
from overseer.fleet.interface import FleetPartUnavailable, FleetStart
from overseer.fleet.workers.answers import receive_answer
from overseer.fleet.workers.launch import ChildProcess, start_child
from overseer.fleet.workers.process import FAILED, READY, run_worker
from overseer.fleet.workers.shared_counts import SharedCounts
from overseer.model.events import PackedRowSink
from overseer.sources.zenoh.relay_items import RelayedFeed
from overseer.sources.zenoh.shared_ring import SUPPORTED as SHARED_RING_SUPPORTED
from overseer.sources.zenoh.shared_ring import SharedRing

log = logging.getLogger(__name__)

START_TIMEOUT_SECONDS = 60.0
ANSWER_TIMEOUT_SECONDS = 30.0  # a worker that takes longer to answer is taken for hung and restarted
SUPERVISE_INTERVAL_SECONDS = 0.2
RESTART_DELAY_SECONDS = 1.0  # at most one restart a second per worker, so a crashing one cannot spin


class Relay(Protocol):
    """What hands a transport's samples from the exporter's process to each worker (DDS's, Zenoh's)."""

    def attach(self, worker: int, feed: RelayedFeed) -> None:
        """Worker `worker`, started or started again, reads its batches from `feed` from now on."""

    def start(self) -> None:
        """Join the middleware in the background (an error when its configuration is unusable)."""

    def stop(self) -> None:
        """Leave the middleware, then close every worker's pipe."""


class Answer(NamedTuple):
    """One worker's answer: which worker, which of its incarnations (restarts so far), and the value."""

    worker: int
    generation: int
    value: Any


class WorkersUnavailable(FleetPartUnavailable):
    """Some worker could not answer (it is restarting or hung): its part of the fleet is unknown now."""


class WorkerStartError(RuntimeError):
    """A worker could not start (a bad DDS or Zenoh configuration, say); the message says why."""


@dataclass
class _Handle:
    """One worker's process and pipes; replaced whole when the worker is restarted."""

    index: int
    generation: int  # how many times this worker was restarted before this process
    process: ChildProcess
    requests: Connection
    events: Connection
    lock: threading.Lock = field(default_factory=threading.Lock)
    ready: bool = False


class WorkerPool:
    """Runs `config.ingest.workers` workers; each follows the robots of its own part of the shard."""

    def __init__(
        self,
        config: Config,
        events: PackedRowSink | None = None,
        start: Callable[[], FleetStart] | None = None,
        relays: Mapping[str, Relay] | None = None,
    ) -> None:
        """Prepare the workers of `config`; `events` receives every worker's events, packed (None: dropped).

        `start` tells what a worker follows before it hears anything, asked anew for each worker started
        (a restarted worker follows the inventory and the robots remembered now); `relays`, by transport,
        send each worker started its robots' samples of that transport.
        """
        self.config = config
        self._start = start or FleetStart
        self.count = config.ingest.workers
        self.restarts = [0] * self.count
        self._events = events
        self._relays = dict(relays or {})
        self._robot_counts = SharedCounts.create(self.count)  # each worker's robots, against the cap
        self._handles: list[_Handle | None] = [None] * self.count
        self._died_at = [0.0] * self.count
        self._restarted_at = [float("-inf")] * self.count
        self._stopping = threading.Event()
        self._supervisor: threading.Thread | None = None

    def start(self) -> None:
        """Start every worker and wait until each follows its robots; `WorkerStartError` if one cannot."""
        started = [self._spawn(index) for index in range(self.count)]
        for handle in started:
            self._await_ready(handle)
        self._supervisor = threading.Thread(target=self._supervise, name="ingest-supervisor", daemon=True)
        self._supervisor.start()
        log.info("ingesting with %d worker processes", self.count)

    def prepare_stop(self) -> None:
        """Restart no worker from now on: the exporter is stopping (and may see its workers end first)."""
        self._stopping.set()

    def stop(self) -> None:
        """Stop the workers: they leave their transports when their request pipe closes."""
        self._stopping.set()
        if self._supervisor is not None:
            self._supervisor.join()  # a restart under way sees `_stopping` within a poll slice
        handles = [handle for handle in self._handles if handle is not None]
        for handle in handles:
            with handle.lock:
                handle.requests.close()
        deadline = time.monotonic() + 5
        for handle in handles:
            handle.process.join(timeout=max(0.0, deadline - time.monotonic()))
            if handle.process.is_alive():
                handle.process.kill()
                handle.process.join(timeout=5)
        self._robot_counts.close()

    def up(self, index: int) -> bool:
        """True while worker `index` runs and has started following its robots."""
        handle = self._handles[index]
        return handle is not None and handle.ready and handle.process.is_alive()

    def pid(self, index: int) -> int | None:
        """The process id of worker `index` now."""
        handle = self._handles[index]
        return None if handle is None else handle.process.pid

    def ask_all(self, kind: str, argument: Any = None) -> list[Answer]:
        """Every worker's answer to one request, asked of all at once; a worker that fails gives none."""
        handles = [handle for handle in self._handles if handle is not None and handle.ready]
        asked: list[_Handle] = []
        answers = []
        try:
            for handle in handles:
                handle.lock.acquire()
                if self._request(handle, kind, argument):
                    asked.append(handle)
                else:
                    handle.lock.release()
            while asked:
                handle = asked[0]
                try:
                    answer = self._receive(handle, kind)
                finally:
                    asked.pop(0)
                    handle.lock.release()
                if answer is not None:
                    answers.append(Answer(handle.index, handle.generation, answer[0]))
        finally:
            for handle in asked:  # an unexpected error left these unread: their answers are lost, so are they
                self._fail(handle, f"its answer to {kind!r} was not read")
                handle.lock.release()
        return answers

    def ask_every(self, kind: str, argument: Any = None) -> list[Answer]:
        """Every worker's answer, or `WorkersUnavailable` when one cannot give it (restarting, hung)."""
        answers = self.ask_all(kind, argument)
        if len(answers) < self.count:
            missing = sorted(set(range(self.count)) - {answer.worker for answer in answers})
            raise WorkersUnavailable(
                f"ingest worker{'s' if len(missing) > 1 else ''} {missing} did not answer"
            )
        return answers

    def ask(self, index: int, kind: str, argument: Any = None) -> tuple[Any] | None:
        """Worker `index`'s answer in a 1-tuple, or None when it failed to answer."""
        handle = self._handles[index]
        if handle is None or not handle.ready:
            return None
        with handle.lock:
            return self._receive(handle, kind) if self._request(handle, kind, argument) else None

    def _request(self, handle: _Handle, kind: str, argument: Any) -> bool:
        """Send a request to a worker whose lock is held; False when it cannot be asked (it is failed)."""
        if not handle.ready:  # failed while the lock was awaited: a late answer may still be in its pipe
            return False
        try:
            handle.requests.send((kind, argument))
        except (OSError, ValueError):
            self._fail(handle, "its request pipe is closed")
            return False
        return True

    def _receive(self, handle: _Handle, kind: str) -> tuple[Any] | None:
        try:
            if not handle.requests.poll(ANSWER_TIMEOUT_SECONDS):
                self._fail(handle, f"it did not answer {kind!r} within {ANSWER_TIMEOUT_SECONDS:g}s")
                return None
            status, value = receive_answer(handle.requests, ANSWER_TIMEOUT_SECONDS)
        except TimeoutError:
            self._fail(handle, f"it stopped halfway through answering {kind!r}")
            return None
        except (EOFError, OSError, ValueError):
            self._fail(handle, f"it went away while answering {kind!r}")
            return None
        if status != "ok":
            log.error("ingest worker %d could not answer %s: %s", handle.index, kind, value)
            return None
        return (value,)

    def _fail(self, handle: _Handle, why: str) -> None:
        """Take a worker that cannot answer for dead: kill it, and the supervisor restarts it."""
        if handle.process.is_alive() and not self._stopping.is_set():
            log.error(
                "ingest worker %d (pid %s) is failing: %s; killing it", handle.index, handle.process.pid, why
            )
            handle.process.kill()
        handle.ready = False

    def _spawn(self, index: int) -> _Handle:
        made: list[Connection] = []  # every pipe end made, closed again if the worker cannot be started
        rings: list[SharedRing] = []  # the relayed samples' payloads, with each relay's pipe
        # By transport, (the worker's end, the relay's end): the worker reads its robots' samples.
        feeds: dict[str, tuple[RelayedFeed, RelayedFeed]] = {}
        try:
            requests, child_requests = _pipe(made)
            events, child_events = _pipe(made, duplex=False)
            for transport in self._relays:
                relayed, relay_writer = _pipe(made, duplex=False)
                ring = SharedRing.create() if SHARED_RING_SUPPORTED else None
                if ring is not None:
                    rings.append(ring)
                feeds[transport] = (RelayedFeed(relayed, ring), RelayedFeed(relay_writer, ring))
            arguments = (
                self.config,
                index,
                self.count,
                child_requests,
                child_events,
                self._start(),
                {transport: worker_end for transport, (worker_end, _) in feeds.items()},
                self._robot_counts,
            )
            process = start_child(run_worker, arguments)
        except (OSError, RuntimeError) as error:  # out of memory, descriptors or threads
            for end in made:
                end.close()
            for ring in rings:
                ring.close()
            raise WorkerStartError(f"ingest worker {index} could not be started: {error}") from error
        child_requests.close()
        child_events.close()
        for ring in rings:
            ring.close()  # its memory stays mapped, here and in the worker
        for transport, (worker_end, relay_end) in feeds.items():
            worker_end.connection.close()
            self._relays[transport].attach(index, relay_end)
        handle = _Handle(index, self.restarts[index], process, requests, events)
        self._handles[index] = handle
        threading.Thread(
            target=self._relay_events, args=(handle,), name=f"events-{index}", daemon=True
        ).start()
        return handle

    def _await_ready(self, handle: _Handle) -> None:
        try:
            if not handle.requests.poll(START_TIMEOUT_SECONDS):
                raise WorkerStartError(
                    f"ingest worker {handle.index} did not start within {START_TIMEOUT_SECONDS:g}s"
                )
            status, detail = receive_answer(handle.requests, START_TIMEOUT_SECONDS)
        except TimeoutError as error:
            raise WorkerStartError(
                f"ingest worker {handle.index} stopped halfway through saying it started"
            ) from error
        except (EOFError, OSError) as error:
            raise WorkerStartError(
                f"ingest worker {handle.index} exited while starting (exit code {handle.process.exitcode})"
            ) from error
        if status == FAILED:
            raise WorkerStartError(f"ingest worker {handle.index} could not start: {detail}")
        if status != READY:
            raise WorkerStartError(f"ingest worker {handle.index} said {status!r} while starting")
        handle.ready = True

    def _relay_events(self, handle: _Handle) -> None:
        while True:
            try:
                batch = handle.events.recv()
            except (EOFError, OSError):
                handle.events.close()
                return
            if self._events is not None:
                try:
                    self._events(batch)
                except Exception:  # keep reading, or the worker's queue of events would grow for good
                    log.exception("events of ingest worker %d could not be stored", handle.index)

    def _supervise(self) -> None:
        while not self._stopping.wait(SUPERVISE_INTERVAL_SECONDS):
            for index, handle in enumerate(self._handles):
                if handle is None or handle.process.is_alive() or self._stopping.is_set():
                    continue
                now = time.monotonic()
                if not self._died_at[index]:
                    self._died_at[index] = now
                    self._robot_counts.slots[index] = 0  # its robots are no one's until it relearns them
                    log.error(
                        "ingest worker %d (pid %s) exited with code %s; restarting it",
                        index,
                        handle.process.pid,
                        handle.process.exitcode,
                    )
                if now - self._restarted_at[index] >= RESTART_DELAY_SECONDS:
                    try:
                        self._restart(index, handle)
                    except Exception:  # the supervisor must go on watching, and try again
                        log.exception("ingest worker %d could not be restarted; trying again", index)

    def _restart(self, index: int, dead: _Handle) -> None:
        if self._stopping.is_set():
            return
        with dead.lock:
            dead.ready = False
            dead.requests.close()  # its events pipe is closed by its relay thread, at end of file
        self.restarts[index] += 1
        self._restarted_at[index] = time.monotonic()
        try:
            handle = self._spawn(index)
        except WorkerStartError as error:
            log.error("%s; trying again", error)
            return
        self._died_at[index] = 0.0  # a new process runs: its death, if it comes, is told anew
        try:
            self._await_ready(handle)
        except WorkerStartError as error:
            log.error("%s; trying again", error)
            handle.process.kill()
            return
        log.info("ingest worker %d restarted (pid %s)", index, handle.process.pid)


def _pipe(made: list[Connection], duplex: bool = True) -> tuple[Connection, Connection]:
    """A new pipe; both its ends are noted in `made`."""
    ends = Pipe(duplex)
    made.extend(ends)
    return ends
