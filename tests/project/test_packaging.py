"""Packaging: the wheel the image's build stage makes, and the runtime stage's install of it.

No Docker engine runs on this machine, so the image itself is not built here. These tests build the wheel
from exactly the files the build stage copies, with the script the build stage runs, and install it as the
runtime stage does into a fresh venv whose PATH has no C compiler: the step that can break.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from testbed.paths import REPO
from testbed.processes import running_exporter

ROOT = REPO
PAGE_SUFFIXES = {".html", ".js", ".css", ".svg"}
COMPILERS = ["cc", "gcc", "c99", "x86_64-linux-gnu-gcc", "clang"]


def dockerfile_stages() -> list[list[str]]:
    """The Dockerfile's instructions (continuation lines joined), stage by stage."""
    text = re.sub(r"\\\n\s*", "", (ROOT / "Dockerfile").read_text(encoding="utf-8"))
    stages: list[list[str]] = []
    for line in text.splitlines():
        if line.startswith("FROM "):
            stages.append([])
        if line and not line.startswith("#"):
            stages[-1].append(line)
    return stages


def dockerfile_copies() -> list[str]:
    """What the stages copy from the build context (not from another stage)."""
    return [
        source
        for stage in dockerfile_stages()
        for line in stage
        if line.startswith("COPY ") and "--from=" not in line
        for source in line.split()[1:-1]
    ]


def test_the_image_is_built_in_two_stages_the_wheel_by_the_build_script() -> None:
    build, runtime = dockerfile_stages()
    assert build[0] == "FROM python:3.11-bookworm AS build"
    assert "RUN scripts/build-wheel /dist" in build
    assert runtime[0] == "FROM python:3.11-slim-bookworm"
    assert any(line.startswith("COPY --from=build /dist ") for line in runtime)
    install = next(line for line in runtime if line.startswith("RUN pip install"))
    for step in ("-r /tmp/requirements/tools.txt", "-r /tmp/requirements/runtime.txt", "--no-deps /tmp/dist"):
        assert step in install, step
    assert install.count("--require-hashes") == 2


def test_files_the_dockerfile_copies_exist() -> None:
    sources = dockerfile_copies()
    assert sources, "the Dockerfile copies nothing"
    for source in sources:
        assert (ROOT / source).exists(), source


def docker_context(tmp_path: Path) -> Path:
    """The files the Dockerfile copies, as .dockerignore leaves them."""
    context = tmp_path / "context"
    context.mkdir()
    for source in dockerfile_copies():
        path = ROOT / source
        (context / source).parent.mkdir(parents=True, exist_ok=True)
        if path.is_dir():
            shutil.copytree(
                path,
                context / source,
                ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "*.so"),
                dirs_exist_ok=True,
            )
        else:
            shutil.copy(path, context / source)
    return context


def wheel_names(wheel: Path) -> set[str]:
    """The wheel's file names, checked for the status page, the console scripts and stray packages."""
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
    assert {name.split("/")[0] for name in names} == {
        "overseer",
        "overseer-0.1.0.dist-info",
        "overseer-0.1.0.data",
    }, "only the overseer package, its metadata and its scripts"
    return names


def wheel_from_dockerfile_sources(tmp_path: Path, env: dict[str, str] | None = None) -> set[str]:
    """The names in the wheel pip builds from the files the Dockerfile copies, with this venv's tools."""
    context = docker_context(tmp_path)
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            "dist",
            str(context),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    (wheel,) = (tmp_path / "dist").glob("overseer-*.whl")
    return wheel_names(wheel)


def test_package_built_from_dockerfile_sources_has_page_and_scripts_without_docker_engine(
    tmp_path: Path,
) -> None:
    names = wheel_from_dockerfile_sources(tmp_path)
    assert any(re.fullmatch(r"overseer/codec/_cstatus\..*\.so", name) for name in names)
    assert any(re.fullmatch(r"overseer/fleet/_cdeflate\..*\.so", name) for name in names)
    assert any(re.fullmatch(r"overseer/fleet/_cstamps\..*\.so", name) for name in names)


def test_package_builds_without_a_c_compiler_leaving_out_the_compiled_extensions(tmp_path: Path) -> None:
    # A source install on a machine with no gcc: the extension is optional outside the image's build.
    names = wheel_from_dockerfile_sources(tmp_path, {**os.environ, "CC": str(tmp_path / "no-such-gcc")})
    assert not any(name.endswith(".so") for name in names)
    fallbacks = {"overseer/codec/compiled.py", "overseer/fleet/deflated.py", "overseer/fleet/stamps.py"}
    assert fallbacks <= set(names)


def run(args: list[str], env: dict[str, str], cwd: Path | None = None) -> None:
    """Run a build or install step, failing with its output."""
    done = subprocess.run(args, capture_output=True, text=True, timeout=600, env=env, cwd=cwd, check=False)
    assert done.returncode == 0, f"{' '.join(args)}:\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"


def fresh_venv(path: Path) -> Path:
    """A new venv at `path` (from the interpreter running the tests); its bin folder."""
    run([sys.executable, "-m", "venv", str(path)], dict(os.environ))
    return path / "bin"


def without_compiler(bin_dir: Path) -> dict[str, str]:
    """An environment whose PATH is the venv's bin alone: no C compiler to be found, none named."""
    env = {k: v for k, v in os.environ.items() if k not in {"CC", "CXX", "LDSHARED", "PATH"}}
    env["PATH"] = str(bin_dir)
    for compiler in COMPILERS:
        assert shutil.which(compiler, path=env["PATH"]) is None, compiler
    return env


@pytest.mark.servers
def test_the_build_stage_wheel_runs_the_compiled_decoder_where_no_compiler_is(tmp_path: Path) -> None:
    # Build stage: a fresh venv on PATH, and the very script the Dockerfile runs.
    build_bin = fresh_venv(tmp_path / "build")
    context = docker_context(tmp_path)
    build_env = {**os.environ, "PATH": f"{build_bin}:{os.environ['PATH']}"}
    run([str(context / "scripts" / "build-wheel"), str(tmp_path / "dist")], build_env, cwd=context)
    (wheel,) = (tmp_path / "dist").glob("overseer-*.whl")
    names = wheel_names(wheel)
    assert any(re.fullmatch(r"overseer/codec/_cstatus\..*\.so", name) for name in names)
    assert any(re.fullmatch(r"overseer/fleet/_cdeflate\..*\.so", name) for name in names)
    assert any(re.fullmatch(r"overseer/fleet/_cstamps\..*\.so", name) for name in names)

    # Runtime stage: the runtime stage's installs, in a fresh venv with no compiler on PATH.
    runtime_bin = fresh_venv(tmp_path / "runtime")
    env = without_compiler(runtime_bin)
    pip = [str(runtime_bin / "python"), "-m", "pip", "install", "--quiet"]
    run([*pip, "--require-hashes", "-r", str(ROOT / "requirements" / "tools.txt")], env)
    run([*pip, "--require-hashes", "-r", str(ROOT / "requirements" / "runtime.txt")], env)
    run([*pip, "--no-deps", str(wheel)], env)
    run([str(runtime_bin / "python"), "-m", "pip", "check"], env)

    with running_exporter(
        tmp_path, None, "--dds.disabled", command=[str(runtime_bin / "overseer")], env=env
    ) as exp:
        samples = exp.samples()
    assert samples["overseer_build_info"] == {(("codec", "compiled"), ("version", "0.1.0")): 1.0}
    assert "status decoder: compiled" in exp.log()
