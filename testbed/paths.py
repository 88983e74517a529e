"""Where things are in the repository, for the servers the testbed starts and the files they read."""

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TESTBED = REPO / "testbed"
