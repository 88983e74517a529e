"""A worker's process, started without `multiprocessing`'s machinery: the exporter's interpreter, run afresh.

`multiprocessing`'s `spawn` also starts a resource tracker, an interpreter of its own (13 MB resident)
that outlives nothing the workers hold: they share only pipes and memory files (`SharedCounts`,
`SharedRing`), which need no cleanup by a third process. So a worker is a plain child process: its
function and arguments are pickled down a pipe of their own, and the pipes (`Connection`) and memory
files among them are passed as open file descriptors under the same numbers. The child imports what
the exporter imported, from the same path, with the same interpreter options.
"""

from __future__ import annotations

import contextlib
import io
import os
import pickle
import subprocess
import sys
import threading
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection
from typing import IO, Any

from overseer.fleet.workers.shared_counts import SharedCounts
from overseer.sources.zenoh.shared_ring import SharedRing

CHILD_MARKER = __name__  # in every child's command line, to find them by
# The child reads the exporter's import path, then the function and its arguments, from descriptor {}.
_BOOTSTRAP = (
    "import os, pickle, sys; payload = os.fdopen({}, 'rb'); sys.path[:] = pickle.load(payload); "
    f"from {CHILD_MARKER} import run_child; run_child(payload)"
)


class ChildProcess:
    """A started child: its pid, whether it runs, its exit code; killed and waited for like a `Process`."""

    def __init__(self, popen: subprocess.Popen[bytes]) -> None:
        """Follow the child that `popen` started."""
        self._popen = popen
        self.pid = popen.pid

    @property
    def exitcode(self) -> int | None:
        """The child's exit status, or the negated number of the signal that ended it; None while it runs."""
        return self._popen.poll()

    def is_alive(self) -> bool:
        """True until the child has ended (and been reaped)."""
        return self._popen.poll() is None

    def kill(self) -> None:
        """Send the child SIGKILL, unless it has already ended."""
        self._popen.kill()

    def join(self, timeout: float | None = None) -> None:
        """Wait for the child to end, at most `timeout` seconds."""
        with contextlib.suppress(subprocess.TimeoutExpired):
            self._popen.wait(timeout)


def start_child(target: Callable[..., Any], args: Sequence[Any]) -> ChildProcess:
    """Run `target(*args)` in a new interpreter; `target` must be importable by its module's name.

    Every `Connection`, `SharedCounts` and `SharedRing` in `args` is the same pipe or memory in the
    child. Close the parent's copies of the child's pipe ends once this returns, so that either side
    sees the other leave.
    The arguments are written to the child as it reads them, from a thread of their own: a child that
    never starts never answers either, which whoever waits for its answer times out on.
    """
    payload = io.BytesIO()
    passed = _ArgumentPickler(payload)
    pickle.dump(sys.path, payload)
    passed.dump((target, tuple(args)))
    reader, writer = os.pipe()
    try:
        popen = subprocess.Popen(
            [sys.executable, *_interpreter_options(), "-c", _BOOTSTRAP.format(reader)],
            stdin=subprocess.DEVNULL,  # nothing for a worker to read from the exporter's terminal
            pass_fds=[*passed.descriptors, reader],
        )
    except BaseException:
        os.close(writer)
        raise
    finally:
        os.close(reader)
    try:
        threading.Thread(
            target=_write_payload, args=(writer, payload.getbuffer()), name=f"start-{popen.pid}", daemon=True
        ).start()
    except BaseException:  # no thread to write with (RuntimeError): a child left waiting would wait for good
        os.close(writer)
        popen.kill()
        popen.wait()
        raise
    return ChildProcess(popen)


def run_child(payload: IO[bytes]) -> None:
    """In the child: read the function and its arguments from `payload`, then run it."""
    target, args = pickle.load(payload)
    payload.close()
    target(*args)


def _write_payload(descriptor: int, payload: memoryview) -> None:
    # A child that ends before reading all of it (BrokenPipeError) says why by its exit code.
    with contextlib.suppress(BrokenPipeError), open(descriptor, "wb") as stream:
        stream.write(payload)


def _interpreter_options() -> list[str]:
    """The running interpreter's options (`-X dev`, `-W`, `-O`...), passed on as `multiprocessing` does."""
    options: list[str] = subprocess._args_from_interpreter_flags()  # type: ignore[attr-defined]
    return options


class _ArgumentPickler(pickle.Pickler):
    """Pickles pipes and memory files as the file descriptors the child receives under the same numbers."""

    def __init__(self, file: IO[bytes]) -> None:
        super().__init__(file, protocol=pickle.HIGHEST_PROTOCOL)
        self.descriptors: list[int] = []

    def reducer_override(self, obj: Any) -> Any:
        if isinstance(obj, Connection):
            self.descriptors.append(obj.fileno())
            return Connection, (obj.fileno(), obj.readable, obj.writable)
        if isinstance(obj, SharedCounts):
            self.descriptors.append(obj.fileno())
            return SharedCounts, (obj.fileno(), len(obj))
        if isinstance(obj, SharedRing):
            self.descriptors.append(obj.fileno())
            return SharedRing, (obj.fileno(), obj.size)
        return NotImplemented
