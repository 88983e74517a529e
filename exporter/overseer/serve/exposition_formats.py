"""The text formats a scrape can be answered in, and what sets them apart: headers, `# UNIT`, `# EOF`.

Our metric and label names are all in the legacy character set, so a sample line is the same bytes in
the Prometheus text format (0.0.4 and 1.0.0) and in OpenMetrics (0.0.1 and 1.0.0) under every escaping
scheme but `dots` (which doubles underscores, and which we therefore do not offer): only the family
headers and the end differ. The cached per-robot lines serve every format.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from prometheus_client.exposition import generate_latest as generate_text
from prometheus_client.openmetrics.exposition import generate_latest as generate_openmetrics
from prometheus_client.registry import Collector

from overseer.fleet.metric_families import MetricFamily

TEXT_MEDIA_TYPE = "text/plain"
OPENMETRICS_MEDIA_TYPE = "application/openmetrics-text"
# Escaping schemes under which our (legacy) names are written unchanged; a scrape states one.
UNCHANGED_NAME_ESCAPINGS = ("underscores", "allow-utf-8", "values")
DEFAULT_ESCAPING = "underscores"  # what the escaping spec says to assume when none is asked
_OPENMETRICS_END = b"# EOF\n"


@dataclass(frozen=True)
class ExpositionFormat:
    """One format and version; `escaping` is stated in the Content-Type of the 1.0.0 formats only."""

    media_type: str
    version: str
    escaping: str | None = None

    @property
    def openmetrics(self) -> bool:
        """True for OpenMetrics, False for the Prometheus text format."""
        return self.media_type == OPENMETRICS_MEDIA_TYPE

    @property
    def content_type(self) -> str:
        """The Content-Type header of an answer in this format."""
        stated = f"{self.media_type}; version={self.version}; charset=utf-8"
        return stated if self.escaping is None else f"{stated}; escaping={self.escaping}"

    def header(self, family: MetricFamily) -> str:
        """`# HELP`, `# TYPE` (and in OpenMetrics `# UNIT`) of `family`."""
        return _header(family, self.openmetrics)

    def extras(self, registry: Collector) -> bytes:
        """The small collectors beyond the fleet's (event history, Icinga 2 push), by prometheus-client."""
        if not self.openmetrics:
            return generate_text(registry)
        body = generate_openmetrics(registry)  # type: ignore[no-untyped-call]
        return bytes(body[: -len(_OPENMETRICS_END)])  # one `# EOF`, at the very end of the whole answer

    @property
    def end(self) -> bytes:
        """What closes the answer: OpenMetrics' `# EOF`, nothing in the text format."""
        return _OPENMETRICS_END if self.openmetrics else b""


TEXT = ExpositionFormat(TEXT_MEDIA_TYPE, "0.0.4")
OPENMETRICS = ExpositionFormat(OPENMETRICS_MEDIA_TYPE, "1.0.0", DEFAULT_ESCAPING)


@functools.cache
def _header(family: MetricFamily, openmetrics: bool) -> str:
    if openmetrics:
        # OpenMetrics names the family, not its samples, and escapes quotes in the help as well.
        help_text = family.documentation.replace("\\", r"\\").replace("\n", r"\n").replace('"', r"\"")
        unit = f"# UNIT {family.name} {family.unit}\n" if family.unit else ""
        return f"# HELP {family.name} {help_text}\n# TYPE {family.name} {family.kind}\n{unit}"
    help_text = family.documentation.replace("\\", r"\\").replace("\n", r"\n")
    name = family.sample_name
    return f"# HELP {name} {help_text}\n# TYPE {name} {family.kind}\n"
