"""The component keys a model shares across its robots, and the bound on how many it keeps."""

from __future__ import annotations

from overseer.model.component_keys import ComponentKeys


def test_one_name_gets_one_key_tuple() -> None:
    keys = ComponentKeys()
    first = keys.of("/Lidar")
    assert first == ("/Lidar", "")
    assert keys.of("".join(["/", "Lidar"])) is first
    assert keys.of("/Motor") is not first
    assert len(keys) == 2


def test_a_full_table_starts_again_and_keys_stay_right() -> None:
    keys = ComponentKeys(capacity=3)
    names = [f"/hostile/{index}" for index in range(10)]
    handed = [keys.of(name) for name in names]
    assert handed == [(name, "") for name in names]
    assert len(keys) <= 3  # never more than its capacity, however many names a fleet invents
    assert keys.of(names[-1]) is handed[-1]  # the newest names are still shared
    assert keys.of(names[0]) is not handed[0]  # an old one was let go: a tuple of its own now
