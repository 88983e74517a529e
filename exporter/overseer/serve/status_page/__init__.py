"""The fleet status page, served by the exporter itself (no build step, no CDN): its files and headers."""

from __future__ import annotations

from importlib import resources
from typing import NamedTuple

STATIC_PREFIX = "/static/"
CONTENT_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".svg": "image/svg+xml",
}
FAVICON = "favicon.svg"  # also served at /favicon.ico, where browsers and tools look for it unasked
# The page runs only its own files and reads only this exporter: robot text can never become code.
PAGE_HEADERS = (
    (
        "Content-Security-Policy",
        "default-src 'none'; script-src 'self'; style-src 'self'; connect-src 'self'; img-src 'self'; "
        "base-uri 'none'; form-action 'self'; frame-ancestors 'self'",
    ),
    ("X-Content-Type-Options", "nosniff"),
)


class PageFile(NamedTuple):
    """One file of the page as served."""

    body: bytes
    content_type: str


def load_page_files() -> dict[str, PageFile]:
    """Every file of the page by name, as `/static/<name>` serves it, read once at start."""
    files = {}
    for entry in resources.files(__name__).iterdir():
        suffix = "." + entry.name.rpartition(".")[2]
        if entry.is_file() and suffix in CONTENT_TYPES:
            files[entry.name] = PageFile(entry.read_bytes(), CONTENT_TYPES[suffix])
    return files
