"""Each configuration key's entry: its flag, its default as documented, and what it means.

Every section module declares `OPTIONS` beside its fields, one `Option` a key. From them, and nothing
else: `overseer run` registers its flags and turns the flags given into configuration overrides (one loop
each, below), `--help` says what each means, and `make docs` writes the configuration reference. Flags
hand the configuration text as given (a number, a duration, a size): the section's reader parses every
value, from the file or a flag alike, and names the key when it is bad.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from overseer.config.parsers import FlagText

# How a flag carries its value: one value, a value per repetition (a list), or none (the key takes
# `value`: a switch).
FlagKind = Literal["value", "repeated", "switch"]


@dataclass(frozen=True)
class Flag:
    """One command-line flag of a key."""

    name: str  # --fleet.stale-after
    kind: FlagKind = "value"
    metavar: str = "VALUE"
    value: object = True  # what a switch sets the key to


@dataclass(frozen=True)
class Option:
    """One key of the configuration: its dotted name, its default as the reference shows it, its meaning.

    `meaning` is one line, for `--help` and the reference.

    `flags` are its command-line flags (most keys have one, named after the key); none means it is read
    from the file only, and `file_only` says why. `from_flags` turns the values of its flags given into
    the key's value, for a key whose flags do not map one to one onto it.
    """

    key: str  # fleet.stale_after, or log_level at the top
    default: str
    meaning: str
    flags: tuple[Flag, ...] = ()
    file_only: str = ""  # why there is no flag
    from_flags: Callable[[dict[str, Any]], object] | None = field(default=None, compare=False)

    @property
    def section(self) -> str:
        """The section the key is in ('' at the top)."""
        return self.key.partition(".")[0] if "." in self.key else ""


def option(
    key: str,
    default: str,
    meaning: str,
    kind: FlagKind = "value",
    metavar: str = "VALUE",
    flag: str | None = None,
    value: object = True,
) -> Option:
    """An option with one flag, named `--<section>.<key>` with `-` for `_` unless `flag` names it."""
    name = flag or "--" + key.replace("_", "-")
    return Option(key, default, meaning, (Flag(name, kind, metavar, value),))


def file_only(key: str, default: str, meaning: str, why: str) -> Option:
    """An option read from the configuration file only; `why` says why it has no flag."""
    return Option(key, default, meaning, file_only=why)


def add_flags(parser: argparse.ArgumentParser, options: Iterable[Option]) -> None:
    """Register every flag of `options` on `parser`, its help the option's (and its default)."""
    for entry in options:
        for flag in entry.flags:
            text = f"{entry.meaning} (default {entry.default})" if entry.default else entry.meaning
            dest = _dest(flag)
            text = text.replace("%", "%%")  # argparse formats help with %
            if flag.kind == "switch":
                parser.add_argument(flag.name, dest=dest, action="store_const", const=flag.value, help=text)
            elif flag.kind == "repeated":
                parser.add_argument(flag.name, dest=dest, action="append", metavar=flag.metavar, help=text)
            else:
                parser.add_argument(flag.name, dest=dest, metavar=flag.metavar, help=text)


def overrides(args: argparse.Namespace, options: Iterable[Option]) -> dict[str, object]:
    """The dotted keys the flags given in `args` set, with the values as given (the sections parse them)."""
    found: dict[str, object] = {}
    for entry in options:
        given = {flag.name: _as_typed(getattr(args, _dest(flag))) for flag in entry.flags}
        given = {name: value for name, value in given.items() if value is not None}
        if not given:
            continue
        if entry.from_flags is not None:
            found[entry.key] = entry.from_flags(given)
        else:
            [found[entry.key]] = given.values()
    return found


def naming_the_flag(message: str, args: argparse.Namespace, options: Iterable[Option]) -> str:
    """`message`, an error that names a key, naming the flag given for it too (the user typed the flag)."""
    for entry in options:
        rest = message.removeprefix(entry.key)
        if rest == message or rest[:1] not in (":", "["):
            continue
        given = [flag.name for flag in entry.flags if getattr(args, _dest(flag), None) is not None]
        where, _, what = rest.partition(":")
        return f"{', '.join(given)} ({entry.key}{where}):{what}" if given else message
    return message


def flag_names(options: Sequence[Option]) -> list[str]:
    """Every flag of `options`, in order."""
    return [flag.name for entry in options for flag in entry.flags]


def _as_typed(value: object) -> object:
    """A flag's text (or each repetition's) as `FlagText`; a switch's value as it is."""
    if isinstance(value, str):
        return FlagText(value)
    if isinstance(value, list):
        return [_as_typed(item) for item in value]
    return value


def _dest(flag: Flag) -> str:
    return "option_" + flag.name.lstrip("-").replace(".", "__").replace("-", "_")
