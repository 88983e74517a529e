"""Memory: resident bytes per component with 100,000 components, everything the exporter keeps included.

Each robot's arrays arrive as bytes objects of their own and go through the DDS source's ingest into the
model: three arrays a robot, the later ones with other voltages (so that the ingest's changed-status path
and the exposition's partial re-render run too), the exposition rendering after each. The heap is trimmed
before the count, as the exporter trims it every minute (`overseer.heap_trim`).
"""

from __future__ import annotations

import gc
import re

from bench.common import Row, emit, resident_bytes
from overseer.codec.cdr import WIRE_FORMAT, encode_diagnostic_array
from overseer.fleet.exposition import FleetExposition
from overseer.heap_trim import trim_heap
from overseer.ingest.payload import PayloadIngest
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.serve.assembler import ExpositionAssembler
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components

ROBOTS = 2000
LEAVES = 45  # with their 5 groups: 50 components per robot


def main() -> None:
    """Measure and print the rows."""
    leaves = leaf_components(LEAVES)
    statuses = tuple(aggregated_statuses(leaves, initial_levels(leaves, 2, 2), set()))
    model = FleetModel(FleetLimits(max_robots=ROBOTS))
    exposition = FleetExposition(model, re.compile(".*"))
    assembler = ExpositionAssembler(["dds"])
    gc.collect()
    trim_heap()
    before = resident_bytes()
    ingests = [
        PayloadIngest(model, f"robot{robot}", "dds", f"rt/robot{robot}/diagnostics_agg", WIRE_FORMAT)
        for robot in range(ROBOTS)
    ]
    # Three arrays a robot, each with other voltages than the one before, scraped after each.
    for second in range(3):
        for robot, ingest in enumerate(ingests):
            ingest(payload(statuses, f"{11 + robot / ROBOTS + second / 100:.5f}", second))
        assembler.assemble([exposition.render_part()])
    gc.collect()
    trim_heap()  # as the exporter does every minute: the scrapes' passing buffers are no memory it keeps
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


def payload(statuses: tuple[DiagnosticStatus, ...], voltage: str, second: int) -> bytes:
    """An array of `statuses` with every voltage set to `voltage`, serialized as DDS delivers it."""
    varied = tuple(
        s._replace(values=tuple((k, voltage if k == "voltage" else v) for k, v in s.values)) for s in statuses
    )
    return encode_diagnostic_array(DiagnosticArray(second, 0, "", varied))


if __name__ == "__main__":
    main()
