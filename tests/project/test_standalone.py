"""The repository stands alone: nothing it tracks refers to a place outside it."""

from __future__ import annotations

import fnmatch
import re
import subprocess
from pathlib import Path

from testbed.paths import REPO

# A sibling of the checkout, or a directory of some build machine or user account.
OUTSIDE = re.compile(r"\.\./shared\b|(?<![\w.])/(?:work|root|home|Users)/[\w.-]+")
ALLOWED = {"tests/project/test_standalone.py"}


def ignored_patterns(root: Path) -> list[str]:
    """The .gitignore's patterns (names and globs, a trailing / for folders), and git's own folder."""
    lines = (root / ".gitignore").read_text(encoding="utf-8").splitlines()
    return [".git", *(line.strip().rstrip("/") for line in lines if line.strip() and line[0] != "#")]


def tracked_files(root: Path = REPO) -> list[str]:
    """Every file of the project: what git tracks, or in a copy without git (CI), every file not ignored."""
    if (root / ".git").exists():
        listing = subprocess.run(["git", "ls-files", "-z"], cwd=root, capture_output=True, check=True)
        return [name for name in listing.stdout.decode().split("\0") if name]
    patterns = ignored_patterns(root)
    return [
        str(path.relative_to(root))
        for path in root.rglob("*")
        if path.is_file()
        and not any(
            fnmatch.fnmatch(part, pattern) for part in path.relative_to(root).parts for pattern in patterns
        )
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


def test_a_copy_without_git_skips_what_the_build_leaves(tmp_path: Path) -> None:
    (tmp_path / ".gitignore").write_text("*.so\n.venv/\n", encoding="utf-8")
    for name in ("kept.py", "built.so", ".venv/bin/python", "pkg/kept.txt"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("", encoding="utf-8")
    assert sorted(tracked_files(tmp_path)) == [".gitignore", "kept.py", "pkg/kept.txt"]
