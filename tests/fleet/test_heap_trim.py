"""Every exporter process hands freed heap memory back to the system once a minute, from two arenas."""

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


def test_without_mallopt_the_arenas_are_left_as_they_are(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(heap_trim, "_MALLOPT", None)
    assert heap_trim.limit_heap_arenas() is False


def test_without_malloc_trim_nothing_is_started(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(heap_trim, "_TRIM", None)
    assert heap_trim.trim_heap() is False
    assert heap_trim.trim_heap_every() is None


# Threads allocating at once, each from the arena glibc gives it; then glibc's count of its arenas.
_THREADS_ALLOCATING = """
import ctypes, sys, threading
from overseer.heap_trim import limit_heap_arenas

limited = limit_heap_arenas() if sys.argv[1] == "limit" else None
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
together = threading.Barrier(8)

def allocate() -> None:
    together.wait()
    for _ in range(2000):
        libc.malloc(1000)  # kept: ctypes lets go of the interpreter lock, so the threads allocate at once

threads = [threading.Thread(target=allocate) for _ in range(8)]
for thread in threads:
    thread.start()
for thread in threads:
    thread.join()
libc.malloc_stats()  # to stderr, an "Arena N:" paragraph an arena
print(limited)
"""


def run_script(script: str, argument: str, **environment: str) -> subprocess.CompletedProcess[str]:
    """Run `script` with `argument` in a fresh interpreter, no glibc malloc settings but `environment`."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_") and k != "GLIBC_TUNABLES"}
    env["PYTHONPATH"] = str(Path(heap_trim.__file__).parents[1])
    return subprocess.run(
        [sys.executable, "-c", script, argument],
        capture_output=True,
        text=True,
        check=True,
        env={**env, **environment},
    )


def arenas_of_eight_threads(limit: bool, **environment: str) -> tuple[str, int]:
    """What `limit_heap_arenas` said, and how many arenas eight threads allocating at once used."""
    result = run_script(_THREADS_ALLOCATING, "limit" if limit else "leave", **environment)
    return result.stdout.strip(), result.stderr.count("Arena ")


def test_the_threads_of_a_process_share_two_arenas_once_limited() -> None:
    said, arenas = arenas_of_eight_threads(limit=False)
    assert said == "None" and arenas > 2, "these threads took no arenas of their own: nothing to show"
    assert arenas_of_eight_threads(limit=True) == ("True", 2)


def test_an_arena_count_the_environment_sets_is_left_to_glibc() -> None:
    assert arenas_of_eight_threads(limit=True, MALLOC_ARENA_MAX="3") == ("False", 3)
    assert arenas_of_eight_threads(limit=True, GLIBC_TUNABLES="glibc.malloc.arena_max=1") == ("False", 1)


@pytest.fixture
def started(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Which commands shaped their heap and started the trimming thread (neither done here)."""
    calls: list[str] = []
    for module in ("overseer.commands.run", "overseer.commands.demo", "overseer.fleet.workers.process"):
        monkeypatch.setattr(f"{module}.shape_heap", lambda module=module: calls.append(f"{module}: shape"))
        monkeypatch.setattr(f"{module}.trim_heap_every", lambda module=module: calls.append(module))
    return calls


def test_overseer_run_and_demo_trim_their_heap(
    started: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "--config.file", str(tmp_path / "missing.yml")]) == 2
    assert main(["demo", "--web.listen-address", "no port here"]) == 2
    assert started == [
        "overseer.commands.run: shape",
        "overseer.commands.run",
        "overseer.commands.demo: shape",
        "overseer.commands.demo",
    ]
    capsys.readouterr()


def test_an_ingest_worker_trims_its_heap_with_serving_and_exit_stubbed(
    started: list[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(worker_process, "_serve", lambda *_: 0)
    monkeypatch.setattr(os, "_exit", lambda status: None)
    monkeypatch.setattr(logging, "shutdown", lambda: None)  # pytest's own handlers stay open
    worker_process.run_worker(Config(), 0, 2, None, None)  # type: ignore[arg-type]
    assert started == ["overseer.fleet.workers.process: shape", "overseer.fleet.workers.process"]


# A block of megabytes freed between live ones, as a render's pieces are: still resident, or given back.
_LARGE_BLOCK_FREED = """
import ctypes, os, sys
from overseer.heap_trim import map_large_blocks

mapped = map_large_blocks() if sys.argv[1] == "map" else None
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]

def resident() -> int:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")

size = 8 << 20
libc.free(libc.malloc(size))  # glibc mapped it, and from now on takes blocks this large from the heap
block = libc.malloc(size)
assert block, "no memory"
ctypes.memset(block, 1, size)
above = [libc.malloc(100_000) for _ in range(4)]  # live blocks after it: the heap cannot shrink past them
before = resident()
libc.free(block)
print(mapped, before - resident())
"""


def resident_bytes_given_back(map_blocks: bool, **environment: str) -> tuple[str, int]:
    """What `map_large_blocks` said, and the resident bytes freeing an 8 MB block between others gave back."""
    said, given_back = run_script(
        _LARGE_BLOCK_FREED, "map" if map_blocks else "leave", **environment
    ).stdout.split()
    return said, int(given_back)


def test_a_large_block_freed_between_live_ones_is_given_back_once_large_blocks_are_mapped() -> None:
    said, given_back = resident_bytes_given_back(map_blocks=False)
    assert said == "None" and given_back < 1 << 20, "glibc gave it back anyway: nothing to show"
    said, given_back = resident_bytes_given_back(map_blocks=True)
    assert said == "True" and given_back >= 8 << 20


@pytest.mark.parametrize(
    "setting",
    [
        {"MALLOC_MMAP_THRESHOLD_": str(16 << 20)},
        {"GLIBC_TUNABLES": f"glibc.malloc.mmap_threshold={16 << 20}"},
        {"MALLOC_TOP_PAD_": str(16 << 20)},
    ],
)
def test_large_blocks_are_left_as_the_environment_says(setting: dict[str, str]) -> None:
    said, given_back = resident_bytes_given_back(map_blocks=True, **setting)
    assert said == "False" and given_back < 1 << 20
