"""Where the tests' own files are: golden outputs and schemas."""

from testbed.paths import REPO

TESTS = REPO / "tests"
GOLDEN = TESTS / "golden"
SCHEMAS = TESTS / "schemas"
