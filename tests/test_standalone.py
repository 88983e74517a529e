"""The repository stands alone: nothing it tracks refers to a place outside it."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# A sibling of the checkout, or a directory of some build machine or user account.
OUTSIDE = re.compile(r"\.\./shared\b|(?<![\w.])/(?:work|root|home|Users)/[\w.-]+")
ALLOWED = {"tests/test_standalone.py"}
# What a checkout grows that is not the project's: CI runs on a copy without .git, so it walks the tree.
GENERATED = {".git", ".venv", ".mypy_cache", ".pytest_cache", ".ruff_cache", "__pycache__", "build"}


def tracked_files() -> list[str]:
    """Every file of the project: what git tracks, or in a copy without git, every file not generated."""
    if (REPO / ".git").exists():
        listing = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True)
        return [name for name in listing.stdout.decode().split("\0") if name]
    return [
        str(path.relative_to(REPO))
        for path in REPO.rglob("*")
        if path.is_file()
        and not GENERATED.intersection(path.relative_to(REPO).parts)
        and not any(part.endswith(".egg-info") for part in path.parts)
    ]


def test_no_tracked_file_names_a_path_outside_the_repository() -> None:
    offenders = []
    for name in tracked_files():
        path = REPO / name
        if name in ALLOWED or not path.is_file():
            continue
        text = path.read_bytes().decode("utf-8", errors="replace")
        offenders += [f"{name}: {match.group()}" for match in OUTSIDE.finditer(text)]
    assert offenders == []


def test_the_pattern_catches_what_it_is_for() -> None:
    assert OUTSIDE.search("see [notes](../shared/ARCHITECTURE.md)")
    assert OUTSIDE.search("the venv is /work/main/.venv")
    assert OUTSIDE.search("cd /root/project")
    assert not OUTSIDE.search("ln -s /usr/lib/nagios/plugins/ and /etc/icinga2/conf.d")
