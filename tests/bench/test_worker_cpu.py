"""Where an exporter's CPU goes: its own process and its workers apart, and each worker count against one."""

from __future__ import annotations

import pytest

import bench.worker_cpu
from bench.common import Row
from bench.worker_cpu import (
    BUSIEST_WORKER_A_MESSAGE,
    OWN_PROCESS_A_MESSAGE,
    STEADY_CPU_A_MESSAGE,
    WORKERS_LEFT_OUT,
    ProcessesCpu,
    compared_with_one_worker,
)

EXPORTERS = (100, 200)  # two shards' exporters


def read_processes(
    monkeypatch: pytest.MonkeyPatch, trees: dict[int, list[int]], cpu: dict[int, float]
) -> None:
    """Each exporter's process tree and each process's CPU seconds, as /proc would give them now."""
    monkeypatch.setattr(bench.worker_cpu, "process_tree", lambda pid: trees[pid])
    monkeypatch.setattr(bench.worker_cpu, "cpu_seconds", lambda pid: cpu[pid])


def test_the_exporters_own_processes_are_told_from_their_workers_and_a_restarted_worker_is_left_out(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    read_processes(
        monkeypatch, {100: [100, 101, 102], 200: [200, 201]}, {100: 5, 101: 1, 102: 2, 200: 7, 201: 0}
    )
    processes = ProcessesCpu(EXPORTERS)
    # 102 ended and 103 took its place; the others went on
    read_processes(
        monkeypatch,
        {100: [100, 101, 103], 200: [200, 201]},
        {100: 5.5, 101: 1.75, 103: 0.25, 200: 7.5, 201: 1.0},
    )
    split = processes.stop()
    assert split.own == 1.0  # 0.5 + 0.5, the two exporters' own processes
    assert sorted(split.workers) == [0.75, 1.0]  # 101 and 201: whole in the window
    assert split.whole == 1.0 + 0.75 + 1.0 + 0.25  # the new worker's time is all in the window
    assert split.left_out == 2  # the one that ended, the one that started

    rows = {row.figure: row for row in split.rows("f", messages_a_second=1e6 / split.seconds)}
    assert rows[f"f: {OWN_PROCESS_A_MESSAGE}"].value == pytest.approx(1.0)  # µs a message
    assert rows[f"f: {BUSIEST_WORKER_A_MESSAGE}"].value == pytest.approx(1.0)
    assert rows[f"f: {WORKERS_LEFT_OUT}"].value == 2


def test_an_exporter_that_ingests_in_its_own_process_tells_no_part(monkeypatch: pytest.MonkeyPatch) -> None:
    read_processes(monkeypatch, {100: [100]}, {100: 1.0})
    processes = ProcessesCpu(EXPORTERS[:1])
    read_processes(monkeypatch, {100: [100]}, {100: 1.5})
    split = processes.stop()
    assert split.whole == split.own == 0.5
    assert split.rows("f", 1000) == []


def measured(label: str, steady: float, busiest: float | None) -> list[Row]:
    """A run's rows as bench_scale names them, with its steady figure and its busiest worker's."""
    rows = [Row("scale", f"{label}: {STEADY_CPU_A_MESSAGE}", steady, "µs")]
    if busiest is not None:
        rows.append(Row("scale", f"{label}: {BUSIEST_WORKER_A_MESSAGE}", busiest, "µs"))
    return rows


def test_each_worker_count_is_compared_with_the_nearest_run_of_one_worker() -> None:
    runs = [
        (1, measured("f, 1 worker", 80.0, None)),
        (2, measured("f, 2 workers", 88.0, 40.0)),
        (1, measured("f, 1 worker", 100.0, None)),
        (4, measured("f, 4 workers", 120.0, 27.5)),
    ]
    rows = {row.figure: (row.value, row.target) for row in compared_with_one_worker("f", ", h", runs)}
    assert rows == {
        "f, 2 workers ÷ 1 worker, h, same invocation: exporter CPU a message, steady": (
            1.1,
            "~ 1 divided, ~ 2 multiplied",
        ),
        "f, 2 workers ÷ 1 worker, h, same invocation: the busiest worker's": (
            0.5,
            "<= 0.50 divided, ~ 1 multiplied",
        ),
        "f, 4 workers ÷ 1 worker, h, same invocation: exporter CPU a message, steady": (
            1.2,
            "~ 1 divided, ~ 4 multiplied",
        ),
        "f, 4 workers ÷ 1 worker, h, same invocation: the busiest worker's": (
            0.275,
            "<= 0.25 divided, ~ 1 multiplied",
        ),
    }


def test_nothing_is_compared_without_a_run_of_one_worker_or_a_figure_to_compare() -> None:
    two = (2, measured("f, 2 workers", 88.0, 40.0))
    assert compared_with_one_worker("f", "", [two]) == []
    assert compared_with_one_worker("f", "", [(1, measured("f, 1 worker", 0.0, None)), two]) == []
    assert compared_with_one_worker("f", "", [(1, measured("f, 1 worker", 80.0, None)), (2, [])]) == []
    restarted = [*two[1], Row("scale", f"f, 2 workers: {WORKERS_LEFT_OUT}", 2, "processes")]
    assert compared_with_one_worker("f", "", [(1, measured("f, 1 worker", 80.0, None)), (2, restarted)]) == []


def test_a_worker_that_ended_in_the_window_is_neither_told_apart_nor_in_the_whole(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    read_processes(monkeypatch, {100: [100, 101, 102]}, {100: 1.0, 101: 1.0, 102: 1.0})
    processes = ProcessesCpu(EXPORTERS[:1])
    read_processes(monkeypatch, {100: [100, 101]}, {100: 1.5, 101: 2.0})
    split = processes.stop()
    assert (split.whole, split.own, split.workers, split.left_out) == (1.5, 0.5, (1.0,), 1)
