"""One key tuple per component name, shared by every robot of a model that reports that name.

A fleet's robots report the same names: at 10,000 robots of 50 components a tuple of its own for each
component's key was 56 bytes of every component's memory, the same two strings over and over.
"""

from __future__ import annotations

from overseer.model.state import ComponentKey

# Names kept for sharing: a fleet's robots of a few kinds report a few thousand. Past it the table starts
# again: a name may be 1,024 characters, and the table keeps a name after every robot reporting it went.
MAX_SHARED_KEYS = 10_000


class ComponentKeys:
    """The key of a component known by its name alone, one tuple per name across the fleet."""

    def __init__(self, capacity: int = MAX_SHARED_KEYS) -> None:
        """Share up to `capacity` names' keys at a time."""
        self._capacity = capacity
        self._keys: dict[str, ComponentKey] = {}

    def __len__(self) -> int:
        """How many names' keys are kept for sharing now."""
        return len(self._keys)

    def of(self, name: str) -> ComponentKey:
        """The key `(name, "")`: the same tuple for every robot, while the table holds it."""
        key = self._keys.get(name)
        if key is None:
            if len(self._keys) >= self._capacity:
                # A fleet of ever-new names (a hostile one) starts sharing anew instead of growing the
                # table: components keep the keys they have, and later robots share new ones.
                self._keys.clear()
            key = self._keys[name] = (name, "")
        return key
