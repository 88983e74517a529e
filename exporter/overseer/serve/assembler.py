"""One exposition from rendered parts (one per ingest worker): headers once, lines of every part, counters.

The same parts make any format the scrape asked for: the formats differ only in their headers and end.
A gzip answer is laid together from the parts' deflated lines without compressing them again. After the
exporter's own families come the extra collectors' (by prometheus-client), then the families their
owners render and keep themselves (a line a robot: the maintenance state).
"""

from __future__ import annotations

import functools
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from typing import NamedTuple, Protocol

from prometheus_client.registry import Collector, CollectorRegistry

from overseer import __version__
from overseer.codec import compiled
from overseer.fleet import metric_families as contract
from overseer.fleet.deflated import Deflated, deflate, gzip_member_strings, inflate_in_slices
from overseer.fleet.exposition import ExpositionPart, escape_label_value, go_float
from overseer.fleet.metric_families import MetricFamily
from overseer.fleet.metric_values import DROP_REASONS, message_counts
from overseer.serve.exposition_formats import TEXT, ExpositionFormat


class RenderedFamilies(Protocol):
    """Families whose owner renders them, in any format, as text or as a deflated piece."""

    def text(self, fmt: ExpositionFormat) -> bytes:
        """The families' headers and lines in `fmt`."""
        ...  # pragma: no cover

    def deflated(self, fmt: ExpositionFormat) -> Deflated:
        """`text(fmt)`, deflated as a piece of a gzip answer."""
        ...  # pragma: no cover


class ExpositionAssembler:
    """Joins parts (robots disjoint) into one exposition; counters are summed, extra collectors appended."""

    def __init__(
        self,
        transports: Iterable[str],
        extra_collectors: Iterable[Collector] = (),
        external_url: str | None = None,
        rendered: Iterable[RenderedFamilies] = (),
    ) -> None:
        """Zero message counts for `transports`, the web info; then `extra_collectors`, then `rendered`."""
        self._rendered = tuple(rendered)
        self._extra = CollectorRegistry(auto_describe=False)
        for collector in extra_collectors:
            self._extra.register(collector)
        self._transports = tuple(transports)
        self._web_info = (
            ""
            if external_url is None
            else f'overseer_web_info{{external_url="{escape_label_value(external_url)}"}} 1.0\n'
        )

    def assemble(self, parts: Sequence[ExpositionPart], fmt: ExpositionFormat = TEXT) -> bytes:
        """The exposition in `fmt`: each family's header, then every part's lines of it; then the rest."""
        return b"".join(self.text_body(parts, fmt).strings)

    def assemble_gzip(self, parts: Sequence[ExpositionPart], fmt: ExpositionFormat = TEXT) -> bytes:
        """`assemble`'s answer gzipped, from the parts' deflated lines as they are: only the rest is new."""
        return b"".join(self.gzip_body(parts, fmt).strings)

    def text_body(self, parts: Sequence[ExpositionPart], fmt: ExpositionFormat = TEXT) -> Body:
        """`assemble`'s answer to be written out as it is inflated (a large piece a slice at a time).

        At 10,000 robots the text is 170 MB: held whole, it would more than double the exporter's memory
        for every scrape that does not take gzip. A damaged piece is found only as it is written, so the
        answer then ends short of its length (`ValueError`), after its status and headers: the client
        sees a failed transfer instead of a closed connection.
        """
        texts: list[bytes | Deflated] = []
        for index, family in enumerate(contract.FLEET_FAMILIES):
            texts.append(fmt.header(family).encode())
            texts.extend(part.families[index] for part in parts)
        texts.append(self._rest(parts, fmt))
        texts.extend(families.text(fmt) for families in self._rendered)
        texts.append(fmt.end)
        length = sum(len(text) if isinstance(text, bytes) else text.size for text in texts)
        return Body(length, coalesced(_inflated_in_turn(texts)))

    def gzip_body(self, parts: Sequence[ExpositionPart], fmt: ExpositionFormat = TEXT) -> Body:
        """`assemble_gzip`'s answer as the strings it is made of: the parts' deflated lines not copied."""
        pieces: list[Deflated] = []
        for index, family in enumerate(contract.FLEET_FAMILIES):
            pieces.append(_deflated_header(family, fmt))
            pieces.extend(part.families[index] for part in parts)
        pieces.append(deflate(self._rest(parts, fmt)))
        pieces.extend(families.deflated(fmt) for families in self._rendered)
        pieces.append(_deflated_end(fmt))
        strings = gzip_member_strings(pieces)
        return Body(sum(map(len, strings)), coalesced(strings))

    def _rest(self, parts: Sequence[ExpositionPart], fmt: ExpositionFormat) -> bytes:
        """What follows the fleet's families: the exporter's own, the extra collectors'."""
        return self._exporter_families(parts, fmt).encode() + fmt.extras(self._extra)

    def _exporter_families(self, parts: Sequence[ExpositionPart], fmt: ExpositionFormat) -> str:
        message_totals: Counter[tuple[str, str]] = Counter()
        dropped: Counter[str] = Counter()
        errors: Counter[tuple[str, str]] = Counter()
        forgotten: Counter[str] = Counter()
        for part in parts:
            message_totals.update(part.message_counts)
            dropped.update(part.dropped_statuses)
            errors.update(part.source_errors)
            forgotten.update(part.forgotten)
        truncated = sum(part.truncated_strings for part in parts)
        lines = [fmt.header(contract.MESSAGES)]
        for (transport, result), count in message_counts(message_totals, self._transports):
            lines.append(
                f'overseer_messages_total{{result="{escape_label_value(result)}",'
                f'transport="{escape_label_value(transport)}"}} {go_float(float(count))}\n'
            )
        lines.append(fmt.header(contract.STATUSES_DROPPED))
        for reason in DROP_REASONS:
            dropped_count = go_float(float(dropped[reason]))
            lines.append(f'overseer_statuses_dropped_total{{reason="{reason}"}} {dropped_count}\n')
        lines.append(fmt.header(contract.STRINGS_TRUNCATED))
        lines.append(f"overseer_strings_truncated_total {go_float(float(truncated))}\n")
        lines.append(fmt.header(contract.SOURCE_ERRORS))
        for (transport, reason), count in sorted(errors.items()):
            lines.append(
                f'overseer_source_errors_total{{reason="{escape_label_value(reason)}",'
                f'transport="{escape_label_value(transport)}"}} {go_float(float(count))}\n'
            )
        lines.append(fmt.header(contract.ROBOTS_FORGOTTEN))
        for reason in contract.FORGET_REASONS:
            forgotten_count = go_float(float(forgotten[reason]))
            lines.append(f'overseer_robots_forgotten_total{{reason="{reason}"}} {forgotten_count}\n')
        lines.append(fmt.header(contract.BUILD_INFO))
        lines.append(
            f'overseer_build_info{{codec="{compiled.implementation()}",'
            f'version="{escape_label_value(__version__)}"}} 1.0\n'
        )
        lines.append(fmt.header(contract.WEB_INFO))
        lines.append(self._web_info)
        return "".join(lines)


class Body(NamedTuple):
    """An answer's body: its length in bytes, and the byte strings to write one after the other (once)."""

    length: int
    strings: Iterator[bytes]


WRITE_BYTES = 1 << 16  # strings shorter are joined before they are written: a send (a TLS record) each


def coalesced(strings: Iterable[bytes]) -> Iterator[bytes]:
    """`strings` in order, the short ones joined together up to `WRITE_BYTES`; the long ones as they are."""
    short: list[bytes] = []
    size = 0
    for string in strings:
        if len(string) >= WRITE_BYTES:
            if short:
                yield b"".join(short)
                short, size = [], 0
            yield string
            continue
        short.append(string)
        size += len(string)
        if size >= WRITE_BYTES:
            yield b"".join(short)
            short, size = [], 0
    if short:
        yield b"".join(short)


def _inflated_in_turn(texts: Iterable[bytes | Deflated]) -> Iterator[bytes]:
    for text in texts:
        if isinstance(text, bytes):
            yield text
        else:
            yield from inflate_in_slices(text)


@functools.cache
def _deflated_header(family: MetricFamily, fmt: ExpositionFormat) -> Deflated:
    return deflate(fmt.header(family).encode())


@functools.cache
def _deflated_end(fmt: ExpositionFormat) -> Deflated:
    return deflate(fmt.end)
