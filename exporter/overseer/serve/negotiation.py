"""Scrape content negotiation as Prometheus specifies it: the acceptable format weighted highest, else text.

`Accept` lists media ranges with parameters and quality values; Prometheus 2 sends
`application/openmetrics-text;version=1.0.0,application/openmetrics-text;version=0.0.1;q=0.75,
text/plain;version=0.0.4;q=0.5,*/*;q=0.1`, Prometheus 3 adds `text/plain;version=1.0.0` and an
`escaping=` parameter on the 1.0.0 formats. The highest q wins (the earlier range on a tie); a range we
cannot honour (protobuf, another version, the `dots` escaping) is passed over, and when none is left
the answer is the text format 0.0.4, as the specification requires.
"""

from __future__ import annotations

from overseer.serve.exposition_formats import (
    DEFAULT_ESCAPING,
    OPENMETRICS,
    OPENMETRICS_MEDIA_TYPE,
    TEXT,
    TEXT_MEDIA_TYPE,
    UNCHANGED_NAME_ESCAPINGS,
    ExpositionFormat,
)

_ESCAPING_ALIASES = {"allow-utf8": "allow-utf-8"}  # the spelling of an older revision of the spec


def negotiate_format(accept: str | None) -> ExpositionFormat:
    """The format to answer a scrape sending `accept` with."""
    best: tuple[float, ExpositionFormat] | None = None
    for media_range in (accept or "").split(","):
        media_type, parameters = _parse(media_range)
        quality = _quality(parameters)
        if quality is None or quality <= 0:
            continue
        chosen = _format_for(media_type, parameters)
        if chosen is not None and (best is None or quality > best[0]):
            best = (quality, chosen)
    return TEXT if best is None else best[1]


def accepts_gzip(accept_encoding: str | None) -> bool:
    """True when `Accept-Encoding` admits gzip (by name or by `*`) with a quality above zero."""
    wildcard = False
    for coding in (accept_encoding or "").split(","):
        name, parameters = _parse(coding)
        quality = _quality(parameters)
        if name in ("gzip", "x-gzip"):
            return quality is not None and quality > 0
        if name == "*":
            wildcard = quality is not None and quality > 0
    return wildcard


def _parse(item: str) -> tuple[str, dict[str, str]]:
    """A media range's (or coding's) lower-cased name and its parameters, names lower-cased."""
    name, *pairs = item.split(";")
    parameters = {}
    for pair in pairs:
        key, _, value = pair.partition("=")
        parameters[key.strip().lower()] = value.strip().strip('"')
    return name.strip().lower(), parameters


def _quality(parameters: dict[str, str]) -> float | None:
    """The `q` parameter (1 when absent), or None when it is not a number from 0 to 1."""
    text = parameters.get("q")
    if text is None:
        return 1.0
    try:
        quality = float(text)
    except ValueError:
        return None
    return quality if 0 <= quality <= 1 else None


def _format_for(media_type: str, parameters: dict[str, str]) -> ExpositionFormat | None:
    version = parameters.get("version")
    if media_type == OPENMETRICS_MEDIA_TYPE:
        if version in (None, "1.0.0"):
            escaping = _escaping(parameters)
            return None if escaping is None else ExpositionFormat(OPENMETRICS_MEDIA_TYPE, "1.0.0", escaping)
        return ExpositionFormat(OPENMETRICS_MEDIA_TYPE, "0.0.1") if version == "0.0.1" else None
    if media_type == TEXT_MEDIA_TYPE:
        if version in (None, "0.0.4"):
            return TEXT
        if version == "1.0.0":
            escaping = _escaping(parameters)
            return None if escaping is None else ExpositionFormat(TEXT_MEDIA_TYPE, "1.0.0", escaping)
        return None
    if media_type == "application/*":
        return OPENMETRICS
    return TEXT if media_type in ("*/*", "text/*") else None


def _escaping(parameters: dict[str, str]) -> str | None:
    """The escaping scheme to state, or None when the one asked for would change our names."""
    asked = parameters.get("escaping", DEFAULT_ESCAPING).lower()
    asked = _ESCAPING_ALIASES.get(asked, asked)
    return asked if asked in UNCHANGED_NAME_ESCAPINGS else None
