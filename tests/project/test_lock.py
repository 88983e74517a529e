"""The lock: every distribution the venv holds is pinned with hashes, at the versions pyproject.toml asks for.

`make setup` installs requirements/lock.txt (hashes checked) and then the package with no dependencies of its
own to resolve; these tests hold the lock to pyproject.toml and the venv to the lock.
"""

from __future__ import annotations

import re
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import tomllib
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from testbed.paths import REPO

LOCK = REPO / "requirements" / "lock.txt"
SUBSETS = [REPO / "requirements" / "runtime.txt", REPO / "requirements" / "tools.txt"]
PIN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==(\S+)")
HASH = re.compile(r"--hash=sha256:([0-9a-f]{64})")


def locked(path: Path) -> dict[str, tuple[str, frozenset[str]]]:
    """The file's pins: canonical name -> (version, sha256 hashes)."""
    pins: dict[str, tuple[str, frozenset[str]]] = {}
    name = ""
    for line in path.read_text(encoding="utf-8").splitlines():
        if match := PIN.match(line):
            name = canonicalize_name(match[1])
            pins[name] = (match[2], frozenset())
        elif (digest := HASH.search(line)) and name:
            version, hashes = pins[name]
            pins[name] = (version, hashes | {digest[1]})
    return pins


def pyproject_requirements() -> list[Requirement]:
    """The package's dependencies and those of every extra."""
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    extras = project["optional-dependencies"].values()
    return [Requirement(text) for text in [*project["dependencies"], *(t for extra in extras for t in extra)]]


def metadata_folder(distribution: metadata.Distribution) -> str:
    """The name of the distribution's .dist-info (or .egg-info) folder."""
    return Path(str(distribution._path)).name  # type: ignore[attr-defined]


def installed_distributions() -> dict[str, str]:
    """What pip installed into this environment, by canonical name: version.

    Some wheels (ROS 2's) carry other projects' metadata folders among their files; such a folder belongs to
    the wheel that lists it in its RECORD, and is not a distribution of its own.
    """
    distributions = list(metadata.distributions())
    carried = {
        file.parts[0]
        for distribution in distributions
        for file in distribution.files or []
        if file.parts[0] != metadata_folder(distribution)
    }
    return {
        canonicalize_name(distribution.metadata["Name"]): distribution.version
        for distribution in distributions
        if metadata_folder(distribution) not in carried
    }


def test_every_pin_of_pyproject_is_locked_at_that_version() -> None:
    pins = locked(LOCK)
    requirements = pyproject_requirements()
    assert len(requirements) > 10
    for requirement in requirements:
        (specifier,) = requirement.specifier
        assert specifier.operator == "==", f"{requirement}: pyproject.toml pins exact versions"
        name = canonicalize_name(requirement.name)
        assert name in pins, f"{requirement.name} is not in the lock: run `make lock`"
        assert pins[name][0] == specifier.version, (
            f"{requirement} but the lock has {pins[name][0]}: `make lock`"
        )


def test_every_locked_distribution_has_hashes() -> None:
    for path in [LOCK, *SUBSETS]:
        pins = locked(path)
        assert pins, path
        assert [name for name, (_, hashes) in pins.items() if not hashes] == [], path.name


def test_the_runtime_and_tools_files_are_the_lock_at_the_same_versions_and_hashes() -> None:
    pins = locked(LOCK)
    for path in SUBSETS:
        assert {name: pins.get(name) for name in locked(path)} == locked(path), path.name
    assert {"pip", "setuptools", "wheel"} <= set(locked(REPO / "requirements" / "tools.txt"))
    assert {"cyclonedds", "eclipse-zenoh", "prometheus-client"} <= set(locked(SUBSETS[0]))


def test_every_installed_distribution_is_locked_and_every_locked_one_installed() -> None:
    installed = installed_distributions()
    assert installed.pop("overseer") == "0.1.0"
    assert "ros-jazzy-rclpy" in installed and "rclpy" not in installed  # a ROS wheel's inner metadata
    pins = {name: version for name, (version, _) in locked(LOCK).items()}
    assert installed == pins, "the venv and requirements/lock.txt differ: `make setup` installs the lock"


def test_pip_check_finds_nothing_broken() -> None:
    check = subprocess.run(
        [sys.executable, "-m", "pip", "check"], capture_output=True, text=True, timeout=120
    )
    assert check.returncode == 0, check.stdout + check.stderr
