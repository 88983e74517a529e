"""Build the Fast DDS diagnostics publisher used to stand in for a ROS 2 robot."""

from __future__ import annotations

import fcntl
import hashlib
import subprocess
from pathlib import Path

SOURCE_DIR = Path(__file__).resolve().parent / "fastdds"
SOURCES = ("CMakeLists.txt", "diagnostics.idl", "publisher.cpp")
STAMP_NAME = "sources.sha256"
EXECUTABLE_NAME = "publisher"
BUILD_TIMEOUT_S = 600.0


def sources_digest() -> str:
    """Return a SHA-256 over the names and contents of the publisher's sources."""
    digest = hashlib.sha256()
    for name in SOURCES:
        digest.update(name.encode() + b"\0")
        digest.update((SOURCE_DIR / name).read_bytes() + b"\0")
    return digest.hexdigest()


def run_tool(command: list[str]) -> None:
    """Run a build tool, raising RuntimeError with its combined output on failure."""
    try:
        result = subprocess.run(
            command,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            timeout=BUILD_TIMEOUT_S,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        msg = f"{command[0]} failed: {exc}"
        raise RuntimeError(msg) from exc
    if result.returncode != 0:
        msg = f"{' '.join(command)} exited with {result.returncode}:\n{result.stdout}"
        raise RuntimeError(msg)


def build_fastdds_publisher(build_dir: Path) -> Path:
    """Build (or reuse a build of) the Fast DDS publisher in build_dir; return its path."""
    build_dir.mkdir(parents=True, exist_ok=True)
    executable = build_dir / EXECUTABLE_NAME
    stamp = build_dir / STAMP_NAME
    with (build_dir / ".lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # concurrent callers (e.g. xdist) build once
        digest = sources_digest()
        if executable.is_file() and stamp.is_file() and stamp.read_text().strip() == digest:
            return executable
        stamp.unlink(missing_ok=True)
        # CMakeLists.txt runs `fastddsgen -replace -d <build_dir>/gen diagnostics.idl` itself.
        run_tool(["cmake", "-S", str(SOURCE_DIR), "-B", str(build_dir), "-DCMAKE_BUILD_TYPE=Release"])
        run_tool(["make", "-C", str(build_dir), "-j2"])
        if not executable.is_file():
            msg = f"build finished but {executable} is missing"
            raise RuntimeError(msg)
        stamp.write_text(digest + "\n")
    return executable
