"""The benchmarks' table prints every row, one the run could not measure (NaN) as well."""

from __future__ import annotations

import io

from bench.common import Row, print_table


def test_a_figure_not_measured_is_printed_as_nan_beside_the_others() -> None:
    rows = [
        Row("scale", "the first look", float("nan"), "s"),
        Row("scale", "updates published", 599_984.0, "messages"),
    ]
    out = io.StringIO()
    print_table(rows, file=out)
    lines = out.getvalue().splitlines()
    assert "nan" in lines[2].split()
    assert "599,984" in lines[3].split()
