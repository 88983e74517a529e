"""Hypothesis strategies for diagnostics messages, shared by the codec tests."""

from __future__ import annotations

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
