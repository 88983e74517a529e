"""A worker's large answer read by the exporter beside busy threads: `Connection.recv` against one call.

The exporter's process reads each ingest worker's exposition part at every scrape: 8 MB a worker of
5,000 robots. Its other threads (the Zenoh relay's, at 10,000 robots) keep the interpreter busy, and a
read that gives the interpreter lock up for every couple of hundred kilobytes waits for it again each
time. A child started by the workers' launcher answers alternately as a `Connection` message and as
`overseer.fleet.workers.answers` writes it; the parent reads each, with 0, 1 and 2 threads beside it
running Python, and prints the medians and their ratio (one run, so the machine's load hits both).
Target: with a busy thread, the one-call read at most half the `Connection`'s time.
"""

from __future__ import annotations

import argparse
import os
import statistics
import threading
import time
from multiprocessing.connection import Connection, Pipe

from bench.common import Row, emit
from overseer.fleet.workers.answers import receive_answer, send_answer
from overseer.fleet.workers.launch import start_child

CONNECTION, ONE_CALL = "Connection.recv", "one call (MSG_WAITALL)"
TARGET = 0.5  # the one-call read against Connection's, with a busy thread beside it


def answer_requests(requests: Connection, size: int) -> None:
    """In the child: answer each request, in the framing it names, until the pipe closes."""
    part = ("ok", os.urandom(size))
    while True:
        try:
            framing = requests.recv()
        except EOFError:
            return
        if framing == CONNECTION:
            requests.send(part)
        else:
            send_answer(requests, part)


def busy(stop: threading.Event) -> None:
    """Keep the interpreter busy, as the relay's threads do, until told to stop."""
    total = 0
    while not stop.is_set():
        for number in range(1000):
            total += number


def read_times(requests: Connection, busy_threads: int, reads: int) -> dict[str, list[float]]:
    """Seconds each read of an answer took, by framing, taking turns, beside `busy_threads` threads."""
    stop = threading.Event()
    threads = [threading.Thread(target=busy, args=(stop,), daemon=True) for _ in range(busy_threads)]
    for thread in threads:
        thread.start()
    times: dict[str, list[float]] = {CONNECTION: [], ONE_CALL: []}
    try:
        for _ in range(reads):
            for framing, times_of in times.items():
                started = time.perf_counter()
                requests.send(framing)
                answer = requests.recv() if framing == CONNECTION else receive_answer(requests, 60.0)
                times_of.append(time.perf_counter() - started)
                assert answer[0] == "ok"
    finally:
        stop.set()
        for thread in threads:
            thread.join()
    return times


def main() -> None:
    """Measure and print the rows."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--megabytes", type=float, default=8.0, help="an answer's size (default 8)")
    parser.add_argument("--reads", type=int, default=9, help="reads of each framing a setting")
    args = parser.parse_args()
    size = int(args.megabytes * 1e6)
    requests, child_requests = Pipe()
    # By its module's name: run as `-m`, this module is `__main__`, which the child cannot import.
    from bench import bench_worker_answers

    child = start_child(bench_worker_answers.answer_requests, (child_requests, size))
    child_requests.close()
    rows = []
    try:
        for busy_threads in (0, 1, 2):
            times = read_times(requests, busy_threads, args.reads)
            medians = {framing: statistics.median(values) for framing, values in times.items()}
            beside = f"{args.megabytes:g} MB answer, {busy_threads} busy thread{'s' * (busy_threads != 1)}"
            for framing, median in medians.items():
                rows.append(Row("worker_answers", f"{beside}: {framing}, median", median * 1e3, "ms"))
            ratio = medians[ONE_CALL] / medians[CONNECTION]
            target = (f"<= {TARGET:g}", ratio <= TARGET) if busy_threads == 1 else ()
            rows.append(Row("worker_answers", f"{beside}: one call / Connection.recv", ratio, "x", *target))
    finally:
        requests.close()
        child.join(10)
        child.kill()
    emit(rows)


if __name__ == "__main__":
    main()
