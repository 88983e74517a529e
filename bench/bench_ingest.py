"""Ingest on one core: statuses decoded and applied per second, against cyclonedds-python's deserializer.

The same payloads go to both: 1,000 robots' /diagnostics_agg arrays of 55 statuses (50 leaves and their
groups), fed through the exporter's own ingest as three kinds of traffic. "republished": each robot's
array again with a new stamp, as an aggregator does every second. "battery voltages changed": every
battery's voltage differs from the array before, as the simulator's --vary-values sends (the table
says how many statuses that changes). "every status changed": each status's message differs from the
one before, the worst case, where everything must be decoded. The worst case runs twice: with the
compiled status decoder (the normal install) and with the pure-Python one (`OVERSEER_PURE_PYTHON=1`, or
an install without a C compiler).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable

from bench.common import Row, emit, interleaved_rates
from overseer.codec import compiled
from overseer.codec.cdr import WIRE_FORMAT, encode_diagnostic_array
from overseer.codec.wire import decode_array
from overseer.ingest.payload import PayloadIngest
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components
from overseer.sources.dds.types import DiagnosticArray as IdlDiagnosticArray

ROBOTS = 1000
WORST_CASE = "every status changed (worst case)"
WORST_CASE_PURE = "every status changed (worst case), pure-Python decoder"
LEAVES = 50


def fleet_payloads(offset: float, message: str = "") -> tuple[list[bytes], int]:
    """One distinct payload per robot (voltages shifted by `offset`), and the number of statuses in each.

    A non-empty `message` is appended to every status's message.
    """
    leaves = leaf_components(LEAVES)
    statuses = aggregated_statuses(leaves, initial_levels(leaves, 2, 2), set())
    payloads = []
    for robot in range(ROBOTS):
        voltage = f"{11 + robot / ROBOTS + offset:.5f}"
        varied = [
            s._replace(
                message=s.message + message,
                values=tuple((k, voltage if k == "voltage" else v) for k, v in s.values),
            )
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
    one_value = [payloads, fleet_payloads(0.00001)[0]]
    every_status = [fleet_payloads(0.0, " (a)")[0], fleet_payloads(0.0, " (b)")[0]]
    changed_statuses = sum(
        a != b for a, b in zip(decode(one_value[0][0]), decode(one_value[1][0]), strict=True)
    )

    def ingests() -> list[PayloadIngest]:
        model = FleetModel(FleetLimits(max_robots=ROBOTS))
        return [
            PayloadIngest(model, f"robot{i}", "dds", f"rt/robot{i}/diagnostics_agg", WIRE_FORMAT)
            for i in range(ROBOTS)
        ]

    def alternating(versions: list[list[bytes]]) -> Callable[[], int]:
        # Alternate two versions of every array so that each one differs from the one before.
        robots, turn = ingests(), [0]

        def work() -> int:
            turn[0] += 1
            for ingest, payload in zip(robots, versions[turn[0] % 2], strict=True):
                ingest(payload)
            return ROBOTS * per_array

        return work

    def republished() -> Callable[[], int]:
        robots, turn = ingests(), [0]
        for ingest, payload in zip(robots, payloads, strict=True):
            ingest(payload)

        def work() -> int:
            turn[0] += 1
            for ingest, payload in zip(robots, payloads, strict=True):
                ingest(restamped(payload, turn[0]))
            return ROBOTS * per_array

        return work

    def in_pure_python(work: Callable[[], int]) -> Callable[[], int]:
        def pure() -> int:
            previous = compiled.use_compiled(False)
            try:
                return work()
            finally:
                compiled.use_compiled(previous)

        return pure

    def cyclone() -> int:
        for payload in payloads:
            IdlDiagnosticArray.deserialize(payload)
        return ROBOTS * per_array

    one_value_kind = f"battery voltages changed ({changed_statuses} of {per_array} statuses)"
    rates = interleaved_rates(
        {
            "cyclone": cyclone,
            "republished arrays": republished(),
            one_value_kind: alternating(one_value),
            WORST_CASE: alternating(every_status),
            WORST_CASE_PURE: in_pure_python(alternating(every_status)),
        }
    )
    cyclone_rate = rates.pop("cyclone")
    rows = [
        Row("ingest", "cyclonedds-python IdlStruct.deserialize", cyclone_rate, "statuses/s"),
        Row("ingest", "compiled status decoder in use", float(compiled.enabled), "", "1", compiled.enabled),
    ]
    for kind, rate in rates.items():
        # Every figure of the normal install has its target; the pure-Python fallback is reported beside.
        # Without the compiled decoder (not built) the rows without "pure-Python" fall back to it too.
        targeted = kind != WORST_CASE_PURE
        rows += [
            Row(
                "ingest",
                f"{kind}: decoded + applied",
                rate,
                "statuses/s",
                ">= 100,000" if targeted else "",
                rate >= 1e5 if targeted else None,
            ),
            Row(
                "ingest",
                f"{kind} vs cyclonedds deserialize",
                rate / cyclone_rate,
                "x",
                ">= 5" if targeted else "",
                rate / cyclone_rate >= 5 if targeted else None,
            ),
        ]
    emit(rows)


def decode(payload: bytes) -> tuple[DiagnosticStatus, ...]:
    """The statuses of a payload."""
    return decode_array(WIRE_FORMAT, payload).statuses


if __name__ == "__main__":
    main()
