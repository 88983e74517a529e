"""What the exported numbers are: key-values read as numbers, and the message counts every transport shows."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Iterator, Mapping

MESSAGE_RESULTS = ("received", "decode_error", "dropped")
NUMBERED_TRANSPORTS = ("zenoh",)  # whose samples carry sequence numbers: one never heard counts as "lost"
DROP_REASONS = ("robot_limit", "component_limit", "feed_limit", "value_limit", "invalid_level")

_LEADING_NUMBER = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")
_BOOLEANS = {"true": 1.0, "false": 0.0, "True": 1.0, "False": 0.0}


def numeric_value(text: str) -> float | None:
    """The number a key-value's text carries (`12.5`, `12.5 V`, `True`), or None for other text."""
    try:
        return float(text)
    except ValueError:
        pass
    if text in _BOOLEANS:
        return _BOOLEANS[text]
    match = _LEADING_NUMBER.match(text)
    if match is None:
        return None
    value = float(match.group(1))
    return value if math.isfinite(value) else None


class NumericValues:
    """Which key-values are exported, and their numbers; caches the parse of each distinct text."""

    def __init__(self, value_keys: re.Pattern[str]) -> None:
        """Export keys that fully match `value_keys`."""
        self._allowed = value_keys.fullmatch
        self._parsed: dict[str, float | None] = {}

    def pairs(self, values: tuple[tuple[str, str], ...]) -> Iterator[tuple[str, float]]:
        """(key, number) for each allowed key with a numeric value, the first of any repeated key."""
        seen: set[str] = set()
        for key, text in values:
            if key in seen or not self._allowed(key):
                continue
            seen.add(key)
            if text in self._parsed:
                number = self._parsed[text]
            else:
                number = self._parsed[text] = numeric_value(text)
            if number is not None:
                yield key, number


def message_counts(
    counted: Mapping[tuple[str, str], int], transports: Iterable[str]
) -> list[tuple[tuple[str, str], int]]:
    """Message counts by (transport, result), with zeros for every result of the active transports."""
    counts = dict(counted)
    for transport in transports:
        for result in MESSAGE_RESULTS + (("lost",) if transport in NUMBERED_TRANSPORTS else ()):
            counts.setdefault((transport, result), 0)
    return sorted(counts.items())
