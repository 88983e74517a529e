"""Equal sets of names held once, and let go once no holder keeps them."""

from __future__ import annotations

import gc

from overseer.push.shared_sets import NO_NAMES, SharedSets


def test_equal_sets_are_one_object_whatever_their_order_or_spelling() -> None:
    sets = SharedSets()
    first = sets.share(["Power", "Motor"])
    # Names built at run time, as a JSON answer or a listing would give them: equal, not the same objects.
    again = sets.share({"".join(["Mo", "tor"]), "".join(["Pow", "er"])})
    assert again is first and again == frozenset({"Power", "Motor"})
    power = sets.share(["Power"])
    assert power is not first and len(sets) == 2


def test_a_set_no_holder_keeps_is_let_go() -> None:
    sets = SharedSets()
    held = sets.share(["Power", "Motor"])
    sets.share(["Camera"])  # held by no one
    gc.collect()
    assert len(sets) == 1
    del held
    gc.collect()
    assert len(sets) == 0


def test_no_names_are_the_one_empty_set() -> None:
    assert SharedSets().share([]) is NO_NAMES and not NO_NAMES
