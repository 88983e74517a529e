"""The compiled decoder keeps one copy of the key-values that robots repeat, and a bounded number of them.

A fleet's robots report the same values (a camera's fps, a motor's state) for hours; the model holds
one copy of each instead of one a robot. Values that never repeat are soon no longer looked up, long
texts and long values tuples are never kept, and no table grows past its limit, whatever the fleet
sends. Every test starts from tables as at import (`forget_shared`): what earlier tests decoded, and the
records of keys that rarely repeated, would otherwise decide what these find shared.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import pytest

from overseer.codec import cdr, compiled
from overseer.codec.wire import decode_array
from overseer.ingest.payload import PayloadIngest
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from support.codec_paths import codec_path


@pytest.fixture(autouse=True)
def tables_as_at_import() -> Iterator[None]:
    """Each test starts with nothing shared and no key resting."""
    compiled.forget_shared()
    yield
    compiled.forget_shared()


def decoded(statuses: Iterable[DiagnosticStatus]) -> tuple[DiagnosticStatus, ...]:
    """`statuses` encoded as DDS delivers them, then decoded by the compiled decoder."""
    with codec_path("compiled"):
        return decode_array(cdr.WIRE_FORMAT, payload(statuses)).statuses


def camera(fps: str, state: str = "Streaming") -> DiagnosticStatus:
    """A camera's status with two key-values."""
    return DiagnosticStatus(0, "/Camera/Cam1", "Streaming", "camera1", (("state", state), ("fps", fps)))


def payload(statuses: Iterable[DiagnosticStatus], stamp: int = 0) -> bytes:
    """An array of `statuses` as DDS delivers it."""
    return cdr.encode_diagnostic_array(DiagnosticArray(stamp, 0, "", tuple(statuses)))


def held_values(model: FleetModel, robot: str) -> tuple[tuple[str, str], ...]:
    """The values of the one component `robot` reported."""
    (state,) = [r for r in model.snapshot().robots if r.name == robot]
    (component,) = state.components.values()
    return component.values


def insertions(sizes: list[int]) -> int:
    """How many items a table took in, from its size before and after each step (a drop: it started again)."""
    total, last = 0, sizes[0]
    for size in sizes[1:]:
        total += size - last if size >= last else size
        last = size
    return total


def test_two_robots_reporting_the_same_values_hold_one_copy_of_them() -> None:
    model = FleetModel(FleetLimits())
    with codec_path("compiled"):
        for stamp, robot in enumerate(("robot_a", "robot_b")):
            PayloadIngest(model, robot, "dds", f"rt/{robot}/diagnostics", cdr.WIRE_FORMAT)(
                payload([camera("30.0")], stamp)
            )
    a, b = held_values(model, "robot_a"), held_values(model, "robot_b")
    assert a == b == (("state", "Streaming"), ("fps", "30.0"))
    assert a is b


def test_a_value_that_differs_leaves_the_pairs_beside_it_shared() -> None:
    (first,) = decoded([camera("30.0")])
    (second,) = decoded([camera("29.5")])
    assert second.values == (("state", "Streaming"), ("fps", "29.5"))
    assert second.values is not first.values
    assert second.values[0] is first.values[0]
    assert second.values[1] is not first.values[1]


def test_the_pure_python_decoder_gives_equal_statuses() -> None:
    encoded = payload([camera("30.0"), camera("30.0", state="Stopped")])
    with codec_path("compiled"):
        shared = decode_array(cdr.WIRE_FORMAT, encoded)
    with codec_path("python"):
        reference = decode_array(cdr.WIRE_FORMAT, encoded)
    assert shared == reference


def test_long_texts_and_long_values_tuples_are_not_kept() -> None:
    long_value = "x" * (compiled.SHARED_TEXT - len("log") + 1)
    wide = tuple((f"cell{n}", "3.7") for n in range(compiled.SHARED_PAIRS + 1))
    statuses = [
        DiagnosticStatus(0, "/logger", "", "", (("log", long_value),)),
        DiagnosticStatus(0, "/battery", "", "", wide),
    ]
    first, second = decoded(statuses), decoded(statuses)
    assert first == second == tuple(statuses)
    assert first[0].values[0] is not second[0].values[0]
    assert first[1].values is not second[1].values
    assert all(a is b for a, b in zip(first[1].values, second[1].values, strict=True))
    assert compiled.shared_sizes() == (compiled.SHARED_PAIRS + 1, 0)


def test_values_that_never_repeat_are_soon_no_longer_looked_up() -> None:
    measured = 10_000
    sizes = [compiled.shared_sizes()[0]]
    for start in range(0, measured, 100):
        decoded(
            DiagnosticStatus(0, f"/odometer{n}", "", "", (("odometer_never_repeats", f"{n}.5"),))
            for n in range(start, start + 100)
        )
        sizes.append(compiled.shared_sizes()[0])
    # A window of 64 lookups, then 1,024 items unshared: about 640 of the 10,000 taken in.
    assert insertions(sizes) < measured // 8


def test_no_table_grows_past_its_limit_while_values_repeat_enough_to_be_shared() -> None:
    largest_pairs = largest_values = 0
    for start in range(0, compiled.SHARED_PAIRS_LIMIT * 2, 250):
        # Each value four times in a row: three in four lookups find an equal, so sharing goes on.
        decoded(
            DiagnosticStatus(0, "/counter", "", "", (("count_repeated", str(n)),))
            for n in range(start, start + 250)
            for _ in range(4)
        )
        pairs, values = compiled.shared_sizes()
        largest_pairs, largest_values = max(largest_pairs, pairs), max(largest_values, values)
    assert compiled.SHARED_PAIRS_LIMIT // 2 < largest_pairs <= compiled.SHARED_PAIRS_LIMIT
    assert compiled.SHARED_VALUES_LIMIT // 2 < largest_values <= compiled.SHARED_VALUES_LIMIT
