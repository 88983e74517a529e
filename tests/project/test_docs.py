"""The documents hold every fact a user needs and point only to what exists.

The README is a page; the rest lives in docs/, bench/README.md and CONTRIBUTING.md. These tests fail when
a metric the exporter serves, a flag of a command or of the check, or a link target is missing from them,
and when a document names an `overseer run` flag that no longer exists.
"""

from __future__ import annotations

import argparse
import re
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest

from overseer.check.plugin import LONG_OPTIONS
from overseer.cli import COMMANDS, parser_of
from overseer.config.loading import ALL_OPTIONS
from overseer.fleet.metric_families import CONTRACT_FAMILIES
from testbed.paths import REPO
from testbed.ports import free_port
from testbed.processes import running_exporter

README = REPO / "README.md"
DOCUMENTS = (
    README,
    REPO / "CONTRIBUTING.md",
    REPO / "bench" / "README.md",
    *sorted((REPO / "docs").glob("*.md")),
)
README_MAX_LINES = 200
_LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
_SECTION_FLAG = re.compile(
    r"--(?:"
    + "|".join(sorted({o.key.split(".")[0] for o in ALL_OPTIONS if "." in o.key}))
    + r")\.[a-z0-9_.-]*[a-z0-9_]"
)
_FAMILY_HELP = re.compile(r"^# HELP (\S+) ", re.MULTILINE)


def documents_text() -> str:
    """Every document, joined."""
    return "\n".join(path.read_text(encoding="utf-8") for path in DOCUMENTS if path.is_file())


def command_flags(
    parser: argparse.ArgumentParser | None = None, command: str = "overseer"
) -> Iterator[tuple[str, str]]:
    """(command, long flag) for every long flag of every `overseer` command and action."""
    for action in (parser or parser_of(COMMANDS))._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, subparser in action.choices.items():
                yield from command_flags(subparser, f"{command} {name}")
        for flag in action.option_strings:
            if flag.startswith("--") and flag not in ("--help", "--version"):
                yield command, flag


def test_there_are_the_documents_the_readme_sends_a_reader_to() -> None:
    for path in DOCUMENTS:
        assert path.is_file(), path
    assert len(DOCUMENTS) >= 10


def test_the_readme_fits_on_a_page() -> None:
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines; move reference matter to docs/"


def test_the_readme_shows_the_status_page() -> None:
    targets = [image for _, image in _LINK.findall(README.read_text(encoding="utf-8")) if image]
    assert any(target.endswith(".png") and (REPO / target).is_file() for target in targets), targets


@pytest.mark.parametrize("command, flag", sorted(set(command_flags())))
def test_every_flag_of_every_command_is_documented(command: str, flag: str) -> None:
    assert re.search(re.escape(flag) + r"(?![a-z0-9_.-])", documents_text()), f"{command} {flag}"


@pytest.mark.parametrize("flag", sorted(LONG_OPTIONS))
def test_every_option_of_the_check_is_documented(flag: str) -> None:
    assert re.search(re.escape(flag) + r"(?![a-z0-9_-])", documents_text()), f"check_ros_diagnostics {flag}"


def test_no_document_names_a_flag_that_overseer_run_does_not_have() -> None:
    flags = {flag for _, flag in command_flags()}
    named = set(_SECTION_FLAG.findall(documents_text()))
    assert named, "the section flags are not found in the documents at all"
    assert named <= flags, sorted(named - flags)


def test_the_contracts_metric_families_are_documented() -> None:
    text = documents_text()
    missing = [family.name for family in CONTRACT_FAMILIES if family.name not in text]
    assert not missing, missing


def test_every_metric_an_exporter_with_every_output_serves_is_documented(tmp_path: Path) -> None:
    """An exporter with workers, event history, maintenance, an Icinga 2 push and Alertmanager silences on."""
    silent = f"http://127.0.0.1:{free_port()}"  # nothing listens: the outputs count their failures
    password = tmp_path / "icinga2-password"
    password.write_text("secret\n")
    with (
        running_exporter(
            tmp_path,
            None,
            "--dds.domain=231",
            "--ingest.workers=2",
            f"--icinga2.url={silent.replace('http', 'https')}",
            "--icinga2.username=overseer",
            f"--icinga2.password-file={password}",
            "--icinga2.ca-file=/etc/ssl/certs/ca-certificates.crt",
            f"--alertmanager.url={silent}",
        ) as exporter,
        urllib.request.urlopen(exporter.url + "/metrics", timeout=10) as response,
    ):
        exposition = response.read().decode()
    families = set(_FAMILY_HELP.findall(exposition))
    assert {
        "ros_diagnostics_robot_up",
        "overseer_ingest_workers",
        "overseer_events_written_total",
    } <= families
    text = documents_text()
    missing = sorted(family for family in families if not re.search(re.escape(family) + r"(?![a-z_])", text))
    assert not missing, missing


def slug(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*]|\[([^\]]*)\]\([^)]*\)", r"\1", heading).strip().lower()  # markup, not text
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """The anchors of `path`'s headings, numbered as GitHub numbers repeats."""
    seen: dict[str, int] = {}
    result = set()
    in_code = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            in_code = not in_code
        match = None if in_code else _HEADING.match(line)
        if match:
            base = slug(match.group(2))
            count = seen.get(base, 0)
            seen[base] = count + 1
            result.add(base if count == 0 else f"{base}-{count}")
    return result


def relative_links() -> Iterator[tuple[Path, str]]:
    """(document, target) of every link in a document to something of this repository."""
    for path in filter(Path.is_file, DOCUMENTS):  # a missing one fails the test of the documents
        for text_link, image in _LINK.findall(path.read_text(encoding="utf-8")):
            target = text_link or image
            if not re.match(r"[a-z]+:", target):
                yield path, target


@pytest.mark.parametrize(
    "document, target", sorted(set(relative_links())), ids=lambda value: str(value).replace(str(REPO), "")
)
def test_every_link_between_documents_leads_somewhere(document: Path, target: str) -> None:
    file_part, _, anchor = target.partition("#")
    destination = (document.parent / file_part).resolve() if file_part else document
    assert destination.exists(), f"{document.relative_to(REPO)} links to {target}, which does not exist"
    if anchor and destination.suffix == ".md":
        assert anchor in anchors(destination), f"{document.relative_to(REPO)}: no heading for #{anchor}"
