"""A fleet model rendered two ways: by production and by the prometheus-client oracle."""

from __future__ import annotations

import re
import zlib
from collections.abc import Iterable

from prometheus_client.registry import Collector

from overseer.fleet.exposition import FleetExposition
from overseer.fleet.message_labels import DEFAULT_MESSAGE_LABELS, MessageLabels
from overseer.model import FleetModel
from overseer.serve.assembler import ExpositionAssembler
from overseer.serve.exposition_formats import OPENMETRICS, TEXT, ExpositionFormat
from support.oracle import OracleCollector, oracle_openmetrics, oracle_registry, oracle_text

FORMATS = (TEXT, OPENMETRICS)


class Rendering:
    """`model` rendered by the cached renderer and assembler, and by the oracle, in either format."""

    def __init__(
        self,
        model: FleetModel,
        value_keys: str = ".*",
        transports: Iterable[str] = ("dds",),
        extra_collectors: Iterable[Collector] = (),
        *,
        messages: MessageLabels = DEFAULT_MESSAGE_LABELS,
        external_url: str | None = None,
        level_changes: bool = True,
    ) -> None:
        """Render `model` exporting the key-values `value_keys` matches, with these collectors appended."""
        pattern = re.compile(value_keys)
        transports, extra = tuple(transports), tuple(extra_collectors)
        self.exposition = FleetExposition(model, pattern, messages=messages, level_changes=level_changes)
        self.assembler = ExpositionAssembler(transports, extra, external_url)
        oracle = OracleCollector(
            model,
            pattern,
            transports,
            messages=messages,
            external_url=external_url,
            level_changes=level_changes,
        )
        self.registry = oracle_registry(oracle, *extra)

    def fast(self, fmt: ExpositionFormat = TEXT) -> bytes:
        """Production's exposition now; its gzip answer (checked here) holds the same bytes."""
        parts = [self.exposition.render_part()]
        plain = self.assembler.assemble(parts, fmt)
        assert gunzip_one_member(self.assembler.assemble_gzip(parts, fmt)) == plain
        return plain

    def oracle(self, fmt: ExpositionFormat = TEXT) -> bytes:
        """prometheus-client's exposition now."""
        return oracle_openmetrics(self.registry) if fmt.openmetrics else oracle_text(self.registry)

    def both(self, fmt: ExpositionFormat = TEXT) -> tuple[bytes, bytes]:
        """Production's and the oracle's exposition now, production first."""
        return self.fast(fmt), self.oracle(fmt)


def gunzip_one_member(body: bytes) -> bytes:
    """The text of `body`, which must be exactly one gzip member (curl and browsers read only the first)."""
    reader = zlib.decompressobj(31)
    text = reader.decompress(body)
    assert reader.eof and not reader.unused_data, "not exactly one whole gzip member"
    return text


def render(model: FleetModel, value_keys: str = ".*", fmt: ExpositionFormat = TEXT) -> str:
    """Production's exposition of `model`, as text."""
    return Rendering(model, value_keys).fast(fmt).decode("utf-8")
