"""Every exporter process hands freed heap memory back to the system once a minute."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from overseer import heap_trim
from overseer.cli import main
from overseer.config import Config
from overseer.fleet.workers import process as worker_process

# A backlog's worth of samples freed between live objects, then the heap trimmed: what RSS says.
_FRAGMENTED_HEAP = """
import os
from overseer.heap_trim import trim_heap

def resident() -> int:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")

blocks = [bytearray(60_000) for _ in range(4000)]  # 240 MB, each below glibc's mmap threshold
kept = blocks[::20]  # one in twenty stays, so the free space lies between live blocks
del blocks
before = resident()
trimmed = trim_heap()
print(trimmed, before, resident(), len(kept))
"""


def test_freed_memory_between_live_blocks_goes_back_to_the_system_once_trimmed() -> None:
    result = subprocess.run(
        [sys.executable, "-c", _FRAGMENTED_HEAP],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONPATH": str(Path(heap_trim.__file__).parents[1])},
    )
    trimmed, before, after, _ = result.stdout.split()
    assert trimmed == "True"
    assert int(before) > 200e6, "the freed blocks were not kept by the heap: nothing to show"
    assert int(before) - int(after) > 150e6, (before, after)


def test_the_trimming_thread_trims_at_its_interval(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[int] = []

    def trim(pad: int) -> int:
        calls.append(pad)
        return 1

    monkeypatch.setattr(heap_trim, "_TRIM", trim)
    stop = threading.Event()
    thread = heap_trim.trim_heap_every(0.05, stop)
    assert thread is not None and thread.daemon and thread.name == "heap-trim"
    try:
        deadline = time.monotonic() + 5
        while len(calls) < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        stop.set()
        thread.join(5)
    assert calls[:3] == [0, 0, 0]
    assert not thread.is_alive()


def test_a_process_starts_one_trimming_thread_however_often_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(heap_trim, "_trimming", False)
    monkeypatch.setattr(heap_trim, "_trim_loop", lambda interval, stop: None)  # started, and ends at once
    assert heap_trim.trim_heap_every() is not None
    assert heap_trim.trim_heap_every() is None


def test_without_malloc_trim_nothing_is_started(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(heap_trim, "_TRIM", None)
    assert heap_trim.trim_heap() is False
    assert heap_trim.trim_heap_every() is None


@pytest.fixture
def started(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Which commands started the trimming thread (the thread itself is not started)."""
    calls: list[str] = []
    for module in ("overseer.commands.run", "overseer.commands.demo", "overseer.fleet.workers.process"):
        monkeypatch.setattr(f"{module}.trim_heap_every", lambda module=module: calls.append(module))
    return calls


def test_overseer_run_and_demo_trim_their_heap(
    started: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "--config.file", str(tmp_path / "missing.yml")]) == 2
    assert main(["demo", "--web.listen-address", "no port here"]) == 2
    assert started == ["overseer.commands.run", "overseer.commands.demo"]
    capsys.readouterr()


def test_an_ingest_worker_trims_its_heap_with_serving_and_exit_stubbed(
    started: list[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(worker_process, "_serve", lambda *_: 0)
    monkeypatch.setattr(os, "_exit", lambda status: None)
    monkeypatch.setattr(logging, "shutdown", lambda: None)  # pytest's own handlers stay open
    worker_process.run_worker(Config(), 0, 2, None, None)  # type: ignore[arg-type]
    assert started == ["overseer.fleet.workers.process"]
