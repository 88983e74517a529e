"""JSON parsing for the check without the `json` package.

Importing `json` (and with it `re`) costs more than all the rest of the check; CPython's C scanner,
`_json`, does the whole job on its own.
"""

from __future__ import annotations

import _json

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing (14 ms)
if TYPE_CHECKING:
    from typing import Any, ClassVar

_WHITESPACE = " \t\n\r"


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not valid JSON")


class _Context:
    """The attributes `_json.make_scanner` reads from a `json.JSONDecoder`."""

    strict = True
    object_hook = None
    object_pairs_hook = None
    parse_float = float
    parse_int = int
    parse_constant = staticmethod(_reject_constant)
    memo: ClassVar[dict[str, str]] = {}


_scan = _json.make_scanner(_Context())  # type: ignore[arg-type]  # duck-typed JSONDecoder


def loads(data: bytes) -> Any:
    """The value of one JSON document; ValueError (json's own, with its message) when it is not one."""
    value = _scan_document(data)
    if value is not _MALFORMED:
        return value
    import json  # only a malformed answer pays for it: json words the error

    return json.loads(data)


_MALFORMED = object()


def _scan_document(data: bytes) -> Any:
    try:
        text = data.decode("utf-8")
        start = len(text) - len(text.lstrip(_WHITESPACE))
        value, end = _scan(text, start)
    except Exception:  # whatever went wrong, `loads` has json explain it
        return _MALFORMED
    finally:
        _Context.memo.clear()
    return _MALFORMED if text[end:].strip(_WHITESPACE) else value
