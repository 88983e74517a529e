"""The inventory: 10,000 robots loaded and reloaded, and what it adds to memory and scrapes at 1,000 robots.

Targets: reading an inventory of 10,000 robots and handing it to a fleet of them takes under a second,
first and again (a reload that changes every robot's labels); with every one of 1,000 robots x 50
components listed (three labels, three expected components, all met), the exporter's memory and its
scrape (render and assemble) grow by at most 5 %. Memory is measured in two fresh processes, one
without the inventory and one with it; the scrape times are taken in turns in one process, since this
machine is shared.

    python -m bench.bench_inventory
"""

from __future__ import annotations

import gc
import json
import multiprocessing
import re
import statistics
import tempfile
import time
from pathlib import Path

import yaml

from bench.common import Row, emit, resident_bytes
from overseer.codec.cdr import WIRE_FORMAT, encode_diagnostic_array
from overseer.fleet.exposition import FleetExposition
from overseer.ingest.payload import PayloadIngest
from overseer.inventory.file import load_inventory
from overseer.messages import DiagnosticArray
from overseer.model import FleetLimits, FleetModel, Inventory
from overseer.serve.assembler import ExpositionAssembler
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components

LISTED = 10_000
ROBOTS = 1_000
LEAVES = 45  # with their 5 groups: 50 components per robot
ROUNDS = 5


def inventory_text(robots: int, site_suffix: str = "") -> str:
    """An inventory of `robots` robots over two sites and two models, each model expecting three."""
    lines = [
        "models:",
        "  tb4:",
        "    labels: {vendor: clearpath}",
        "    expected: [/Power, {prefix: /Motor/, at_least: 2}, {regex: '/Temp/Sensor[0-9]+', at_least: 1}]",
        "  arm:",
        "    labels: {vendor: acme}",
        "    expected: [/Power, {prefix: /Motor/, at_least: 2}, {regex: '/Temp/Sensor[0-9]+', at_least: 1}]",
        "robots:",
    ]
    for robot in range(robots):
        site = f"site_{'ab'[robot % 2]}{site_suffix}"
        model = ("tb4", "arm")[robot // 2 % 2]
        lines.append(f"  robot{robot}: {{model: {model}, labels: {{site: {site}, team: team{robot % 7}}}}}")
    return "\n".join(lines) + "\n"


def load_and_reload(as_json: bool) -> list[Row]:
    """Seconds to read 10,000 robots and hand them to a fleet of them, first and again (YAML or JSON)."""
    model = FleetModel(FleetLimits(max_robots=LISTED))
    kind = "JSON" if as_json else "YAML"
    with tempfile.TemporaryDirectory() as directory:
        path = Path(directory) / "inventory.yml"
        first: list[float] = []
        again: list[float] = []
        for round_number in range(ROUNDS):
            text = inventory_text(LISTED, str(round_number))
            path.write_text(json.dumps(yaml.safe_load(text)) if as_json else text, encoding="utf-8")
            started = time.perf_counter()
            model.set_inventory(load_inventory(path))
            (first if round_number == 0 else again).append(time.perf_counter() - started)
    assert len(model.snapshot().robots) == LISTED
    return [
        Row(
            "inventory",
            f"{LISTED:,} robots, {kind}: read and followed, first",
            first[0],
            "s",
            "< 1",
            first[0] < 1,
        ),
        Row(
            "inventory",
            f"{LISTED:,} robots, {kind}: reloaded, every label changed (median)",
            statistics.median(again),
            "s",
            "< 1",
            statistics.median(again) < 1,
        ),
    ]


class Fleet:
    """1,000 robots x 50 components fed through the DDS ingest; listed with labels, or not."""

    def __init__(self, listed: bool) -> None:
        """Every robot's array applied twice."""
        leaves = leaf_components(LEAVES)
        self.statuses = tuple(aggregated_statuses(leaves, initial_levels(leaves, 2, 2), set()))
        self.model = FleetModel(FleetLimits(max_robots=ROBOTS))
        if listed:
            with tempfile.TemporaryDirectory() as directory:
                path = Path(directory) / "inventory.yml"
                path.write_text(inventory_text(ROBOTS), encoding="utf-8")
                self.model.set_inventory(load_inventory(path))
        self.ingests = [
            PayloadIngest(self.model, f"robot{robot}", "dds", f"rt/robot{robot}/diagnostics_agg", WIRE_FORMAT)
            for robot in range(ROBOTS)
        ]
        self.exposition = FleetExposition(self.model, re.compile(".*"))
        for second in range(2):
            self.publish(second)

    def publish(self, second: int) -> None:
        """Every robot's array, its voltages changed (so every robot's lines render again)."""
        voltage = f"{11 + second / 100:.2f}"
        statuses = tuple(
            s._replace(values=tuple((k, voltage if k == "voltage" else v) for k, v in s.values))
            for s in self.statuses
        )
        payload = encode_diagnostic_array(DiagnosticArray(second, 0, "", statuses))
        for ingest in self.ingests:
            ingest(payload)


def _memory_of(listed: bool, answers: multiprocessing.Queue[float]) -> None:
    gc.collect()
    before = resident_bytes()
    fleet = Fleet(listed)
    ExpositionAssembler(["dds"]).assemble([fleet.exposition.render_part()])
    gc.collect()
    answers.put(resident_bytes() - before)


def memory(listed: bool) -> float:
    """Resident bytes a fresh process holds for the fleet (its series rendered once), listed or not."""
    context = multiprocessing.get_context("spawn")
    answers: multiprocessing.Queue[float] = context.Queue()
    process = context.Process(target=_memory_of, args=(listed, answers))
    process.start()
    held = answers.get(timeout=600)
    process.join()
    return held


def scrape_times() -> tuple[float, float]:
    """The median render-and-assemble of a changed fleet, without and with the inventory (seconds).

    One fleet, listed and unlisted in turns, so that both are measured on the same objects in memory.
    """
    fleet = Fleet(True)
    with tempfile.TemporaryDirectory() as directory:
        path = Path(directory) / "inventory.yml"
        path.write_text(inventory_text(ROBOTS), encoding="utf-8")
        inventory = load_inventory(path)
    assembler = ExpositionAssembler(["dds"])
    times: dict[bool, list[float]] = {False: [], True: []}
    for second in range(2, 2 + 4 * ROUNDS):
        listed = second % 2 == 0
        fleet.model.set_inventory(inventory if listed else Inventory())
        fleet.publish(second)
        started = time.perf_counter()
        assembler.assemble([fleet.exposition.render_part()])
        times[listed].append(time.perf_counter() - started)
    return statistics.median(times[False]), statistics.median(times[True])


def main() -> None:
    """Measure and print the rows."""
    rows = load_and_reload(as_json=False) + load_and_reload(as_json=True)
    without, with_inventory = memory(False), memory(True)
    memory_growth = with_inventory / without - 1
    plain, listed = scrape_times()
    scrape_growth = listed / plain - 1
    fleet_size = f"{ROBOTS:,} robots x 50 components"
    rows += [
        Row("inventory", f"{fleet_size}: memory without an inventory", without / 1e6, "MB"),
        Row("inventory", f"{fleet_size}: memory, every robot listed", with_inventory / 1e6, "MB"),
        Row(
            "inventory",
            f"{fleet_size}: memory added",
            memory_growth * 100,
            "%",
            "<= 5",
            memory_growth <= 0.05,
        ),
        Row("inventory", f"{fleet_size}: scrape without an inventory (median)", plain * 1000, "ms"),
        Row("inventory", f"{fleet_size}: scrape, every robot listed (median)", listed * 1000, "ms"),
        Row(
            "inventory",
            f"{fleet_size}: scrape time added",
            scrape_growth * 100,
            "%",
            "<= 5",
            scrape_growth <= 0.05,
        ),
    ]
    emit(rows)


if __name__ == "__main__":
    main()
