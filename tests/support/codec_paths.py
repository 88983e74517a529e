"""Run codec tests on both status decoders: the compiled one (`_cstatus.c`) and the pure-Python reference."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from overseer.codec import compiled

# Both must run: without the compiled decoder built, `codec_path("compiled")` fails rather than skips.
CODEC_PATHS = ["python", "compiled"]


@contextmanager
def codec_path(name: str) -> Iterator[None]:
    """Make the codecs decode with `name` ("python" or "compiled") inside the block."""
    previous = compiled.use_compiled(name == "compiled")
    try:
        yield
    finally:
        compiled.use_compiled(previous)
