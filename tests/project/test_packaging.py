"""Packaging: the wheel the Dockerfile installs carries the status page and both console scripts.

No Docker engine runs on this machine, so the image itself is not built here; this test builds the
same package from exactly the files the Dockerfile copies, which is the step that can break.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

from testbed.paths import REPO

ROOT = REPO
PAGE_SUFFIXES = {".html", ".js", ".css"}


def dockerfile_copies() -> list[str]:
    sources: list[str] = []
    for line in (ROOT / "Dockerfile").read_text().splitlines():
        if line.startswith("COPY "):
            sources.extend(line.split()[1:-1])
    return sources


def test_files_the_dockerfile_copies_exist() -> None:
    sources = dockerfile_copies()
    assert sources, "the Dockerfile copies nothing"
    for source in sources:
        assert (ROOT / source).exists(), source


def wheel_from_dockerfile_sources(tmp_path: Path, env: dict[str, str] | None = None) -> set[str]:
    """The names in the wheel built from the files the Dockerfile copies, as .dockerignore leaves them."""
    context = tmp_path / "context"
    context.mkdir()
    for source in dockerfile_copies():
        path = ROOT / source
        if path.is_dir():
            shutil.copytree(
                path, context / source, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "*.so")
            )
        else:
            shutil.copy(path, context / source)
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "--no-build-isolation",
            "-w",
            str(tmp_path / "dist"),
            str(context),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    (wheel,) = (tmp_path / "dist").glob("overseer-*.whl")
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
        entry_points = next(archive.read(n).decode() for n in names if n.endswith("entry_points.txt"))
    assert "overseer/serve/status_page/index.html" in names
    page_files = {
        p.name for p in (ROOT / "exporter/overseer/serve/status_page").iterdir() if p.suffix in PAGE_SUFFIXES
    }
    assert {"app.js", "style.css"} <= page_files
    for page_file in page_files:  # every file the page loads is in the package
        assert f"overseer/serve/status_page/{page_file}" in names, page_file
    assert "overseer/py.typed" in names
    assert re.search(r"^overseer = overseer\.cli:main$", entry_points, re.M)
    assert "overseer-0.1.0.data/scripts/check_ros_diagnostics" in names
    return names


def test_package_built_from_dockerfile_sources_has_page_and_scripts_without_docker_engine(
    tmp_path: Path,
) -> None:
    names = wheel_from_dockerfile_sources(tmp_path)
    assert any(re.fullmatch(r"overseer/codec/_cstatus\..*\.so", name) for name in names)


def test_package_builds_without_a_c_compiler_leaving_out_the_compiled_decoder(tmp_path: Path) -> None:
    # As in the Dockerfile's python:3.11-slim image, which has no gcc.
    names = wheel_from_dockerfile_sources(tmp_path, {**os.environ, "CC": str(tmp_path / "no-such-gcc")})
    assert not any("_cstatus" in name and name.endswith(".so") for name in names)
    assert "overseer/codec/compiled.py" in names
