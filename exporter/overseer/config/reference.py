"""The configuration reference, written from the sections' `OPTIONS` into docs/configuration.md.

`make docs` runs `python -m overseer.config.reference docs/configuration.md`, which replaces what lies
between the two markers; a test holds the file to what this writes, so the reference cannot drift from the
keys and flags the exporter has.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from pathlib import Path

from overseer.config.loading import ALL_OPTIONS
from overseer.config.options import Option

BEGIN = "<!-- configuration reference: generated from the config sections' tables (make docs) -->"
END = "<!-- end of the generated configuration reference -->"


def reference(options: Iterable[Option] = ALL_OPTIONS) -> str:
    """Markdown: a table a section (the top-level keys among them), every key with its flag and default."""
    sections: dict[str, list[Option]] = {}
    for entry in options:
        sections.setdefault(entry.section, []).append(entry)
    parts = []
    for section, entries in sections.items():
        title = f"`{section}:`" if section else "top level"
        rows = [
            f"| `{entry.key.partition('.')[2] if section else entry.key}` | {_flags(entry)} | "
            f"{_cell(entry.default)} | {_cell(entry.meaning)} |"
            for entry in entries
        ]
        table = ["| key | flag | default | meaning |", "|---|---|---|---|", *rows]
        parts.append("\n".join([f"### {title}", "", *table]))
    return "\n\n".join(parts) + "\n"


def _flags(entry: Option) -> str:
    if not entry.flags:
        return f"none: {entry.file_only}"
    shown = []
    for flag in entry.flags:
        text = flag.name if flag.kind == "switch" else f"{flag.name} {flag.metavar}"
        shown.append(f"`{text}`" + (" (repeatable)" if flag.kind == "repeated" else ""))
    return ", ".join(shown)


def _cell(text: str) -> str:
    """`text` in a table cell: no column break, no HTML tag (`<ID>`, `<instance>`)."""
    return text.replace("|", "\\|").replace("<", "&lt;").replace(">", "&gt;")


def with_reference(document: str) -> str:
    """`document` with the reference between its markers (written after BEGIN when END is missing)."""
    if BEGIN not in document:
        raise ValueError(f"the document has no line {BEGIN!r} to write the reference after")
    head, _, rest = document.partition(BEGIN)
    _, found, tail = rest.partition(END)
    return f"{head}{BEGIN}\n\n{reference()}\n{END}{tail if found else rest}"


def main(argv: list[str]) -> int:
    """Rewrite the reference in the file `argv[0]`."""
    path = Path(argv[0])
    path.write_text(with_reference(path.read_text(encoding="utf-8")), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
