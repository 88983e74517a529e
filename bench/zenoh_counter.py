"""A Zenoh subscriber that only counts samples: what "delivered" means in the load generator's benchmark.

`python -m bench.zenoh_counter ENDPOINT [KEY]` subscribes to KEY (default `0/**`, every robot's
rmw_zenoh keys on domain 0) as a client of the router at ENDPOINT, writes `--ready-file` once declared,
and on SIGTERM prints one JSON line: the samples counted and the CPU it used. With `--tokens` it also
subscribes, with their history, to the diagnostics publishers' liveliness tokens as the exporter does, so
that the router does for it what it does for the exporter: beside the exporter, through the same router,
it is the floor of the samples lost, what the router delivers to a subscriber that costs nothing.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import zenoh
from zenoh.handlers import FifoChannel

from bench.common import repo_on_path
from overseer.sources.zenoh.keys import liveliness_subscription
from testbed.processes import RunningProcess, spawn


def main(argv: Sequence[str] | None = None) -> int:
    """Count samples until SIGTERM or SIGINT; print the count."""
    parser = argparse.ArgumentParser(
        prog="python -m bench.zenoh_counter", description=__doc__.splitlines()[0]
    )
    parser.add_argument("endpoint", help="the router to connect to, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("key", nargs="?", default="0/**", help="key expression to count (default 0/**)")
    parser.add_argument("--ready-file", help="written once the subscriber is declared")
    parser.add_argument("--tokens", action="store_true", help="subscribe to the publishers' tokens too")
    args = parser.parse_args(argv)
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("client"))
    config.insert_json5("connect/endpoints", json.dumps([args.endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    # as the exporter's session (zenoh.shared_memory): every sample crosses the router's link to it whole
    config.insert_json5("transport/shared_memory/enabled", "false")
    session = zenoh.open(config)
    counted = [0]
    subscriber = session.declare_subscriber(args.key, FifoChannel(1 << 16))  # Zenoh's thread never waits

    def count() -> None:
        receive = subscriber.handler.recv
        while True:
            try:
                receive()
            except zenoh.ZError:  # closed
                return
            counted[0] += 1

    threading.Thread(target=count, daemon=True).start()
    if args.tokens:
        session.liveliness().declare_subscriber(liveliness_subscription(0), lambda _: None, history=True)
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    if args.ready_file:
        Path(args.ready_file).write_text("ready\n")
    started = time.process_time()
    stop.wait()
    cpu = time.process_time() - started
    time.sleep(0.5)  # what the channel still holds is counted before the count is printed
    subscriber.undeclare()  # type: ignore[no-untyped-call]
    session.close()  # type: ignore[no-untyped-call]
    print(json.dumps({"samples": counted[0], "cpu_seconds": round(cpu, 3)}), flush=True)
    return 0


@dataclass
class CounterProcess(RunningProcess):
    """A sample counter in a process of its own."""

    ready_file: Path

    def wait_ready(self, timeout: float = 30.0) -> None:
        """Wait until the subscriber is declared."""
        deadline = time.monotonic() + timeout
        while not self.ready_file.exists():
            if self.process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"sample counter not ready:\n{self.log()[-3000:]}")
            time.sleep(0.1)

    def samples(self, timeout: float = 60.0) -> int:
        """Stop counting; the samples counted."""
        self.stop(timeout=timeout)
        lines = [line for line in self.log().splitlines() if line.startswith("{")]
        if not lines:
            raise RuntimeError(f"sample counter printed no count:\n{self.log()[-3000:]}")
        samples: int = json.loads(lines[-1])["samples"]
        return samples


@contextmanager
def running_counter(
    endpoint: str, directory: Path, key: str = "0/**", tokens: bool = False
) -> Iterator[CounterProcess]:
    """A sample counter for the block, subscribed when the block starts, always stopped at its end."""
    stamp = time.monotonic_ns()
    ready_file, log_path = directory / f"counter-{stamp}.ready", directory / f"counter-{stamp}.log"
    args = [sys.executable, "-m", "bench.zenoh_counter", endpoint, key, f"--ready-file={ready_file}"]
    args += ["--tokens"] if tokens else []
    counter = CounterProcess(spawn(args, log_path, env=repo_on_path()), log_path, ready_file)
    try:
        counter.wait_ready()
        yield counter
    finally:
        counter.stop()


if __name__ == "__main__":
    sys.exit(main())
