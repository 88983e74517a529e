"""Ingest on one core: statuses decoded and applied per second, against cyclonedds-python's deserializer.

The same payloads go to both: 1,000 robots' /diagnostics_agg arrays of 55 statuses (50 leaves and their
groups), each robot's battery voltage different in every array, as the simulator's --vary-values sends.
"changed" feeds every array once (each must be decoded); "republished" feeds each robot's array again
with a new stamp, as an aggregator does every second, which the exporter recognises without decoding.
"""

from __future__ import annotations

import os
import struct

from bench.common import Row, best_rate, emit
from overseer.codec.cdr import decode_diagnostic_array, encode_diagnostic_array
from overseer.fleet_design import aggregated_statuses, initial_levels, leaf_components
from overseer.messages import DiagnosticArray
from overseer.model import FleetLimits, FleetModel
from overseer.sources.dds import CDR_STAMP
from overseer.sources.dds_types import DiagnosticArray as IdlDiagnosticArray
from overseer.sources.ingest import PayloadIngest

ROBOTS = 1000
LEAVES = 50


def fleet_payloads(offset: float) -> tuple[list[bytes], int]:
    """One distinct payload per robot (voltages shifted by `offset`), and the number of statuses in each."""
    leaves = leaf_components(LEAVES)
    statuses = aggregated_statuses(leaves, initial_levels(leaves, 2, 2), set())
    payloads = []
    for robot in range(ROBOTS):
        voltage = f"{11 + robot / ROBOTS + offset:.5f}"
        varied = [
            s._replace(values=tuple((k, voltage if k == "voltage" else v) for k, v in s.values))
            for s in statuses
        ]
        payloads.append(encode_diagnostic_array(DiagnosticArray(robot, 0, "", tuple(varied))))
    return payloads, len(statuses)


def restamped(payload: bytes, second: int) -> bytes:
    """The same array with another header stamp."""
    return payload[:4] + struct.pack("<iI", second, 0) + payload[12:]


def main() -> None:
    """Measure and print the rows."""
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core
    payloads, per_array = fleet_payloads(0.0)
    alternates, _ = fleet_payloads(0.00001)
    model = FleetModel(FleetLimits(max_robots=ROBOTS * 2))
    ingests = [
        PayloadIngest(
            model, f"robot{i}", "dds", f"rt/robot{i}/diagnostics_agg", decode_diagnostic_array, CDR_STAMP
        )
        for i in range(ROBOTS)
    ]
    round_number = [0]

    def changed() -> int:
        # Alternate two versions of every array so each call must decode.
        round_number[0] += 1
        for ingest, payload in zip(ingests, payloads if round_number[0] % 2 else alternates, strict=True):
            ingest(payload)
        return ROBOTS * per_array

    def republished() -> int:
        round_number[0] += 1
        for ingest, payload in zip(ingests, payloads, strict=True):
            ingest(restamped(payload, round_number[0]))
        return ROBOTS * per_array

    def cyclone() -> int:
        for payload in payloads:
            IdlDiagnosticArray.deserialize(payload)
        return ROBOTS * per_array

    changed_rate = best_rate(changed)
    for ingest, payload in zip(ingests, payloads, strict=True):
        ingest(payload)
    republished_rate = best_rate(republished)
    cyclone_rate = best_rate(cyclone, repeats=3)
    emit(
        [
            Row("ingest", "cyclonedds-python IdlStruct.deserialize", cyclone_rate, "statuses/s"),
            Row(
                "ingest",
                "changed arrays: decode + apply",
                changed_rate,
                "statuses/s",
                ">= 100,000",
                changed_rate >= 1e5,
            ),
            Row(
                "ingest",
                "changed arrays vs cyclonedds deserialize",
                changed_rate / cyclone_rate,
                "x",
                ">= 5",
                changed_rate / cyclone_rate >= 5,
            ),
            Row(
                "ingest",
                "republished arrays: recognised + applied",
                republished_rate,
                "statuses/s",
                ">= 100,000",
                republished_rate >= 1e5,
            ),
            Row(
                "ingest",
                "republished arrays vs cyclonedds deserialize",
                republished_rate / cyclone_rate,
                "x",
                ">= 5",
                republished_rate / cyclone_rate >= 5,
            ),
        ]
    )


if __name__ == "__main__":
    main()
