"""Memory: resident bytes per component with 100,000 components, everything the exporter keeps included.

Each robot's array arrives as its own bytes object and goes through the DDS source's ingest (decode,
apply, remember a digest) into the model, then the exposition renders once and keeps its cache.
"""

from __future__ import annotations

import gc
import re

from bench.common import Row, emit, resident_bytes
from overseer.codec.cdr import WIRE_FORMAT, encode_diagnostic_array
from overseer.exposition import FleetExposition
from overseer.fleet_design import aggregated_statuses, initial_levels, leaf_components
from overseer.messages import DiagnosticArray
from overseer.model import FleetLimits, FleetModel
from overseer.sources.ingest import PayloadIngest

ROBOTS = 2000
LEAVES = 45  # with their 5 groups: 50 components per robot


def main() -> None:
    """Measure and print the rows."""
    leaves = leaf_components(LEAVES)
    statuses = tuple(aggregated_statuses(leaves, initial_levels(leaves, 2, 2), set()))
    payloads = [encode_diagnostic_array(DiagnosticArray(i, 0, "", statuses)) for i in range(8)]
    model = FleetModel(FleetLimits(max_robots=ROBOTS))
    exposition = FleetExposition(model, re.compile(".*"), ["dds"])
    gc.collect()
    before = resident_bytes()
    ingests = []
    for robot in range(ROBOTS):
        topic = f"rt/robot{robot}/diagnostics_agg"
        ingest = PayloadIngest(model, f"robot{robot}", "dds", topic, WIRE_FORMAT)
        ingest(bytes(bytearray(payloads[robot % len(payloads)])))  # a fresh copy, as DDS delivers it
        ingests.append(ingest)
    exposition.render()
    gc.collect()
    components = sum(len(r.components) for r in model.snapshot().robots)
    per_component = (resident_bytes() - before) / components
    emit(
        [
            Row("memory", "components held", components, "components"),
            Row(
                "memory",
                "resident memory per component",
                per_component,
                "bytes",
                "<= 1,024",
                per_component <= 1024,
            ),
        ]
    )


if __name__ == "__main__":
    main()
