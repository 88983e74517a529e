"""Readers shared by every section: durations, sizes, strings, lists, files; each error names its key."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from overseer.config.errors import ConfigError

_DURATION_PART = re.compile(r"(\d+(?:\.\d+)?)(ms|s|m|h|d)")
_DURATION_UNITS = {"ms": 0.001, "s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}
_SIZE = re.compile(r"(\d+(?:\.\d+)?)\s*(B|kB|KB|MB|GB|TB|KiB|MiB|GiB|TiB)?")
_SIZE_UNITS = {
    None: 1,
    "B": 1,
    "kB": 1000,
    "KB": 1000,
    "MB": 1000**2,
    "GB": 1000**3,
    "TB": 1000**4,
    "KiB": 1024,
    "MiB": 1024**2,
    "GiB": 1024**3,
    "TiB": 1024**4,
}


class FlagText(str):
    """A value as typed after a flag: the readers take the number or boolean it spells, as YAML would.

    A file's quoted `"8"` stays a string and an error, so the file means what its YAML types say.
    """


def _flag_number(value: object) -> object:
    """An integer for a flag's decimal text, else `value` as it is."""
    if isinstance(value, FlagText) and value.strip().isdigit() and len(value) < 20:
        return int(value)
    return value


def parse_duration(value: object, key: str) -> float:
    """Seconds from a number or a Prometheus-style duration such as `5s`, `1h30m`, `250ms`."""
    if isinstance(value, bool):
        raise ConfigError(f"{key}: expected a duration such as 5s, got {value!r}")
    if isinstance(value, int | float):
        seconds = float(value) if abs(value) < 1e300 else float("inf")  # float(10**400) would raise
    elif isinstance(value, str) and value and _DURATION_PART.sub("", value) == "":
        seconds = sum(float(n) * _DURATION_UNITS[u] for n, u in _DURATION_PART.findall(value))
    else:
        raise ConfigError(f"{key}: expected a duration such as 5s, got {value!r}")
    if not seconds > 0 or seconds == float("inf"):
        raise ConfigError(f"{key}: must be a positive duration, got {value!r}")
    return seconds


def parse_size(value: object, key: str, minimum: int, minimum_text: str) -> int:
    """Bytes from a number or a size such as `500MB`, `1GB`, `2GiB`, at least `minimum`."""
    match = _SIZE.fullmatch(value.strip()) if isinstance(value, str) else None
    if isinstance(value, int) and not isinstance(value, bool):
        size = value
    elif match is not None:
        size = int(float(match.group(1)) * _SIZE_UNITS[match.group(2)])
    else:
        raise ConfigError(f"{key}: expected a size such as 500MB or 1GB, got {value!r}")
    if size < minimum:
        raise ConfigError(f"{key}: must be at least {minimum_text}, got {value!r}")
    return size


def section(raw: dict[str, Any], name: str, allowed: set[str]) -> dict[str, Any]:
    """The mapping `raw[name]` (empty when absent), refusing keys outside `allowed`."""
    found = raw.get(name) or {}
    if not isinstance(found, dict):
        raise ConfigError(f"{name}: expected a mapping, got {found!r}")
    reject_unknown(found, name + ".", allowed)
    return found


def reject_unknown(raw: dict[str, Any], prefix: str, allowed: set[str]) -> None:
    """ConfigError for the first key of `raw` outside `allowed`, named with `prefix`."""
    for key in raw:
        if key not in allowed:
            shown = key if isinstance(key, str) and key.isprintable() and key else repr(key)
            raise ConfigError(f"{prefix}{shown}: unknown key (expected one of {', '.join(sorted(allowed))})")


def string(value: object, key: str) -> str:
    """`value` when it is a non-empty string."""
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{key}: expected a non-empty string, got {value!r}")
    return str(value)  # a flag's FlagText as the plain string it is


def boolean(value: object, key: str) -> bool:
    """`value` when it is true or false (a flag's text `true` or `false` too)."""
    if isinstance(value, FlagText) and value.lower() in ("true", "false"):
        return value.lower() == "true"
    if not isinstance(value, bool):
        raise ConfigError(f"{key}: expected true or false, got {value!r}")
    return value


def listed(value: object, key: str) -> list[Any]:
    """`value` when it is a list."""
    if not isinstance(value, list):
        raise ConfigError(f"{key}: expected a list, got {value!r}")
    return value


def positive_integer(value: object, key: str) -> int:
    """`value` when it is a positive integer (not a bool; a flag's decimal text too)."""
    number = _flag_number(value)
    if not isinstance(number, int) or isinstance(number, bool) or number < 1:
        raise ConfigError(f"{key}: expected a positive integer, got {value!r}")
    return number


def whole_number(value: object, key: str, low: int, high: int, what: str = "an integer") -> int:
    """`value` when it is an integer from `low` to `high` (not a bool; a flag's decimal text too)."""
    number = _flag_number(value)
    if not isinstance(number, int) or isinstance(number, bool) or not low <= number <= high:
        raise ConfigError(f"{key}: expected {what} from {low} to {high}, got {value!r}")
    return number


def read_text_file(path: str | Path, key: str) -> str:
    """The UTF-8 text of the file `key` names; ConfigError naming the key when it cannot be read."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except OSError as error:
        raise ConfigError(f"{key}: cannot read {str(path)!r}: {error.strerror}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{key}: {str(path)!r} is not UTF-8 text") from None


def first_line(error: Exception) -> str:
    """An exception's text on one line."""
    return " ".join(str(error).split())
