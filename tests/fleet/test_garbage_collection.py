"""The exporter's processes run the cycle collector after 100,000 new objects, and still collect cycles."""

from __future__ import annotations

import gc
import logging
import os
import weakref
from collections.abc import Iterator
from typing import Any

import pytest

from overseer.cli import main
from overseer.config import Config
from overseer.fleet.workers import process as worker_process
from overseer.garbage_collection import YOUNG_THRESHOLD, collect_in_large_batches


@pytest.fixture
def thresholds(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Python's default thresholds for the test, and the session's own back after it.

    The commands' heap policy (two arenas, a trimming thread) is left out: it would stay with this process.
    """
    for module in ("overseer.commands.run", "overseer.commands.demo", "overseer.fleet.workers.process"):
        monkeypatch.setattr(f"{module}.shape_heap", lambda: None)
        monkeypatch.setattr(f"{module}.trim_heap_every", lambda: None)
    before = gc.get_threshold()
    gc.set_threshold(700, 10, 10)
    yield
    gc.set_threshold(*before)


@pytest.fixture
def collections() -> Iterator[list[int]]:
    """The generations collected while the test runs, in order."""
    collected: list[int] = []

    def record(phase: str, info: dict[str, Any]) -> None:
        if phase == "stop":
            collected.append(info["generation"])

    gc.callbacks.append(record)
    yield collected
    gc.callbacks.remove(record)


def test_young_objects_are_collected_in_batches_of_100_000(thresholds: None, collections: list[int]) -> None:
    collect_in_large_batches()
    gc.collect()
    collections.clear()
    kept: list[list[int]] = [[] for _ in range(YOUNG_THRESHOLD - 10_000)]
    assert collections == []
    kept += [[] for _ in range(20_000)]
    assert collections, "a collection once more than 100,000 new objects live"
    assert len(kept) == YOUNG_THRESHOLD + 10_000


def test_pythons_default_would_have_collected_a_hundred_times(
    thresholds: None, collections: list[int]
) -> None:
    gc.collect()
    collections.clear()
    kept: list[list[int]] = [[] for _ in range(YOUNG_THRESHOLD - 10_000)]
    assert len(collections) >= 100  # what the exporter's thresholds spare it
    assert kept


def test_garbage_in_reference_cycles_is_still_collected_without_being_asked(
    thresholds: None, collections: list[int]
) -> None:
    collect_in_large_batches()
    gc.collect()

    class Node:
        def __init__(self) -> None:
            self.partner: Node | None = None

    first = Node()
    survivor = weakref.ref(first)
    for _ in range(YOUNG_THRESHOLD):  # pairs that point at each other, dropped at once: only cycles hold them
        node, other = first, Node()
        node.partner, other.partner = other, node
        first = Node()
    assert survivor() is None
    assert collections


def test_overseer_run_sets_the_thresholds_before_anything_else(
    thresholds: None, tmp_path: Any, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "--config.file", str(tmp_path / "missing.yml")]) == 2
    assert "missing.yml" in capsys.readouterr().err
    assert gc.get_threshold()[0] == YOUNG_THRESHOLD


def test_overseer_demo_sets_the_thresholds(thresholds: None, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--web.listen-address", "no port here"]) == 2
    assert "listen" in capsys.readouterr().err
    assert gc.get_threshold()[0] == YOUNG_THRESHOLD


def test_an_ingest_worker_sets_the_thresholds_before_it_serves_with_serving_and_exit_stubbed(
    thresholds: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The worker's serving is replaced by a record of the thresholds it would serve with, and its exit
    # (which would end this test's process) by a record of the status.
    served_with: list[int] = []
    exits: list[int] = []

    def serve(*_: object) -> int:
        served_with.append(gc.get_threshold()[0])
        return 0

    monkeypatch.setattr(worker_process, "_serve", serve)
    monkeypatch.setattr(os, "_exit", exits.append)
    monkeypatch.setattr(logging, "shutdown", lambda: None)  # pytest's own handlers stay open
    worker_process.run_worker(Config(), 0, 2, None, None)  # type: ignore[arg-type]
    assert served_with == [YOUNG_THRESHOLD]
    assert exits == [0]
