"""Runs of robots' pieces recompressed as one once they hold still, and the text they stand for."""

from __future__ import annotations

import gzip
from collections.abc import Iterator

from hypothesis import given, settings
from hypothesis import strategies as st

from overseer.fleet.deflated import Deflated, deflate, gzip_member, inflate
from overseer.fleet.joined_runs import MOST_RUN_ROBOTS, RUN_ROBOTS, JoinedRuns
from support.examples import examples


def names_where(ends_run: bool) -> Iterator[str]:
    """Robot names that end a run (or do not), in this process's string hashing."""
    index = 0
    while True:
        name = f"site{index % 7}/robot{index}"
        if (hash(name) % RUN_ROBOTS == 0) is ends_run:
            yield name
        index += 1


def robot_piece(name: str, turn: int = 0) -> Deflated:
    """A robot's lines of a family at some turn of its state: text of a few lines, deflated."""
    return deflate(
        b"".join(
            f'ros_diagnostics_level{{robot="{name}",component="/c{i}"}} {turn}.0\n'.encode() for i in range(5)
        )
    )


def laid_text(pieces: list[Deflated]) -> bytes:
    return b"".join(inflate(piece) for piece in pieces)


def fleet_of(count: int) -> tuple[list[str], list[Deflated]]:
    """`count` robots in runs of a few robots each (every fourth name ends a run)."""
    middles, ends = names_where(False), names_where(True)
    names = [next(ends) if index % 4 == 3 else next(middles) for index in range(count)]
    return names, [robot_piece(name) for name in names]


def test_a_run_that_held_still_for_a_render_is_recompressed_once_and_sent_as_one_piece() -> None:
    names, pieces = fleet_of(40)  # ten runs of four
    runs = JoinedRuns()
    first = runs.join(names, pieces)
    assert runs.recompressed == 0  # nothing known to hold still yet: the pieces as they are
    second = runs.join(names, pieces)
    assert runs.recompressed == 10
    third = runs.join(names, pieces)
    assert runs.recompressed == 10  # kept, not compressed again
    assert inflate(first) == inflate(second) == inflate(third) == laid_text(pieces)
    assert len(second.data) < len(first.data)  # a run is smaller than its robots' pieces apart
    assert third == second


def test_a_changed_robot_sends_its_run_as_pieces_until_it_holds_still_again() -> None:
    names, pieces = fleet_of(40)
    runs = JoinedRuns()
    runs.join(names, pieces)
    joined = runs.join(names, pieces)
    pieces[5] = robot_piece(names[5], turn=1)
    changed = runs.join(names, pieces)
    assert runs.recompressed == 10  # its run is its pieces now; the other nine stay joined
    assert inflate(changed) == laid_text(pieces) != inflate(joined)
    assert len(changed.data) > len(joined.data)
    runs.join(names, pieces)
    assert runs.recompressed == 11  # it held still for a render: joined again, alone


def test_a_robot_rendered_again_to_the_same_bytes_keeps_its_run_joined() -> None:
    names, pieces = fleet_of(8)
    runs = JoinedRuns()
    runs.join(names, pieces)
    runs.join(names, pieces)
    pieces[1] = Deflated(bytes(pieces[1].data), pieces[1].crc, pieces[1].size)  # equal, not the same object
    runs.join(names, pieces)
    assert runs.recompressed == 2


def test_a_family_that_changes_at_every_render_is_never_compressed_twice() -> None:
    names, _ = fleet_of(40)
    runs = JoinedRuns()
    for turn in range(5):
        pieces = [robot_piece(name, turn) for name in names]
        assert inflate(runs.join(names, pieces)) == laid_text(pieces)
    assert runs.recompressed == 0


def test_a_robot_that_comes_or_goes_changes_its_own_run_alone() -> None:
    names, pieces = fleet_of(40)
    runs = JoinedRuns()
    runs.join(names, pieces)
    runs.join(names, pieces)
    newcomer = next(name for name in names_where(False) if name not in names)
    names.insert(13, newcomer)  # inside the fourth run
    pieces.insert(13, robot_piece(newcomer))
    assert inflate(runs.join(names, pieces)) == laid_text(pieces)
    runs.join(names, pieces)
    assert runs.recompressed == 11
    del names[13], pieces[13], names[2], pieces[2]  # it goes, and so does a robot of the first run
    assert inflate(runs.join(names, pieces)) == laid_text(pieces)
    runs.join(names, pieces)
    assert runs.recompressed == 13


def test_no_run_is_longer_than_its_most_robots() -> None:
    middles = names_where(False)
    names = [next(middles) for _ in range(2 * MOST_RUN_ROBOTS + 5)]
    pieces = [robot_piece(name) for name in names]
    runs = JoinedRuns()
    runs.join(names, pieces)
    runs.join(names, pieces)
    assert runs.recompressed == 3


@settings(max_examples=examples(200), deadline=None)
@given(
    renders=st.lists(
        st.tuples(st.lists(st.tuples(st.integers(0, 60), st.integers(0, 2)), max_size=60), st.integers(1, 3)),
        min_size=1,
        max_size=8,
    ),
)
def test_any_renders_answer_a_gzip_stream_of_exactly_the_pieces_text(
    renders: list[tuple[list[tuple[int, int]], int]],
) -> None:
    """Robots by number with a turn of their state, each render repeated a few times (held still)."""
    runs = JoinedRuns()
    for render, times in renders:
        robots = dict(render)  # one piece a robot, in the order the fleet holds them
        names = [f"robot{number}" for number in robots]
        for _ in range(times):
            pieces = [robot_piece(name, turn) for name, turn in zip(names, robots.values(), strict=True)]
            answer = runs.join(names, pieces)
            assert gzip.decompress(gzip_member([answer])) == laid_text(pieces)
