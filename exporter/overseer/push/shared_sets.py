"""Equal sets of names held once: ten thousand robots have a handful of distinct groups and services.

The push keeps, for each robot, the groups it had and the services made and packaged for its host. Held
a set each, with the names as Icinga's answers and each robot's listing spelled them, that was about
24 MB at 10,000 robots; the same few frozensets, shared, are a few kilobytes.
"""

from __future__ import annotations

import weakref
from collections.abc import Iterable

NO_NAMES: frozenset[str] = frozenset()


class SharedSets:
    """Hands out one frozenset for all equal sets of names, for as long as any holder keeps it."""

    def __init__(self) -> None:
        # Keyed by the sorted names, not the set itself: a key held strongly would keep its value alive.
        self._sets: weakref.WeakValueDictionary[tuple[str, ...], frozenset[str]] = (
            weakref.WeakValueDictionary()
        )

    def share(self, names: Iterable[str]) -> frozenset[str]:
        """The frozenset of `names` that every equal set handed out is."""
        members = frozenset(names)
        if not members:
            return NO_NAMES
        key = tuple(sorted(members))
        shared = self._sets.get(key)
        if shared is None:
            self._sets[key] = shared = members
        return shared

    def __len__(self) -> int:
        """How many distinct sets are in use."""
        return len(self._sets)
