"""Hypothesis strategies shared by the tests: diagnostics messages, and payloads damaged on the wire."""

from __future__ import annotations

import struct

from hypothesis import strategies as st

from overseer.messages import DiagnosticArray, DiagnosticStatus

text = st.text(max_size=20)
statuses = st.builds(
    DiagnosticStatus,
    st.integers(min_value=0, max_value=255),
    text,
    text,
    text,
    st.lists(st.tuples(text, text), max_size=3).map(tuple),
)


def arrays(seconds: st.SearchStrategy[int]) -> st.SearchStrategy[DiagnosticArray]:
    """DiagnosticArrays whose stamp seconds come from `seconds` (CDR's are signed, ROS 1's unsigned)."""
    return st.builds(
        DiagnosticArray,
        seconds,
        st.integers(min_value=0, max_value=2**32 - 1),
        text,
        st.lists(statuses, max_size=5).map(tuple),
    )


@st.composite
def damaged(draw: st.DrawFn, payload: bytes) -> bytes:
    """`payload` with bits flipped, cut, bytes spliced in, or a 32-bit word overwritten (lying lengths)."""
    data = bytearray(payload)
    for _ in range(draw(st.integers(min_value=1, max_value=4))):
        if not data:
            break
        at = draw(st.integers(min_value=0, max_value=len(data) - 1))
        kind = draw(st.sampled_from(["flip", "cut", "splice", "word"]))
        if kind == "flip":
            data[at] ^= 1 << draw(st.integers(min_value=0, max_value=7))
        elif kind == "cut":
            del data[at:]
        elif kind == "splice":
            data[at:at] = draw(st.binary(min_size=1, max_size=16))
        else:
            word = draw(
                st.sampled_from([0, 1, 3, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF]) | st.integers(0, 2**32 - 1)
            )
            data[at : at + 4] = struct.pack(draw(st.sampled_from(["<I", ">I"])), word)
    return bytes(data)
