"""A worker's process, started without `multiprocessing`'s machinery: the exporter's interpreter, run afresh.

`multiprocessing`'s `spawn` also starts a resource tracker, an interpreter of its own (13 MB resident)
that outlives nothing the workers hold: they share only pipes and `SharedCounts`, which need no cleanup
by a third process. So a worker is a plain child process: its function and arguments are pickled down
its standard input, and the pipes (`Connection`) and `SharedCounts` among them are passed as open file
descriptors under the same numbers. The child imports what the exporter imported, from the same path.
"""

from __future__ import annotations

import contextlib
import io
import os
import pickle
import subprocess
import sys
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection
from typing import IO, Any

from overseer.fleet.workers.shared_counts import SharedCounts

_BOOTSTRAP = (
    "import pickle, sys; sys.path[:] = pickle.load(sys.stdin.buffer); "
    "from overseer.fleet.workers.launch import run_child; run_child(sys.stdin.buffer)"
)
CHILD_MARKER = "overseer.fleet.workers.launch"  # in every child's command line, to find them by


class ChildProcess:
    """A started child: its pid, whether it runs, its exit code; killed and waited for like a `Process`."""

    def __init__(self, popen: subprocess.Popen[bytes]) -> None:
        """Follow the child that `popen` started."""
        self._popen = popen
        self.pid = popen.pid

    @property
    def exitcode(self) -> int | None:
        """The child's exit status, minus the signal that ended it; None while it runs."""
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

    Every `Connection` and `SharedCounts` in `args` is the same pipe or memory in the child. Close the
    parent's copies of the child's pipe ends once this returns, so that either side sees the other leave.
    """
    payload = io.BytesIO()
    passed = _ArgumentPickler(payload)
    passed.dump((target, tuple(args)))
    popen = subprocess.Popen(
        [sys.executable, "-c", _BOOTSTRAP],
        stdin=subprocess.PIPE,
        pass_fds=passed.descriptors,
    )
    assert popen.stdin is not None
    # A child that ends before reading (BrokenPipeError) says why by its exit code and its pipes' end.
    with contextlib.suppress(BrokenPipeError):
        pickle.dump(sys.path, popen.stdin)
        popen.stdin.write(payload.getbuffer())
    with contextlib.suppress(BrokenPipeError):
        popen.stdin.close()
    return ChildProcess(popen)


def run_child(stream: IO[bytes]) -> None:
    """In the child: read the function and its arguments from `stream`, then run it."""
    target, args = pickle.load(stream)
    stream.close()
    nothing = os.open(os.devnull, os.O_RDONLY)  # nothing else comes from the exporter that way
    os.dup2(nothing, 0)
    os.close(nothing)
    target(*args)


class _ArgumentPickler(pickle.Pickler):
    """Pickles pipes and shared counts as the file descriptors the child receives under the same numbers."""

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
        return NotImplemented
