"""The check's command line and its HTTP plumbing, without an exporter."""

from __future__ import annotations

import subprocess
import sys

import pytest

from overseer import __version__
from overseer.check.plugin import main, options_from_flags, parse_flags
from overseer.verdict import CRITICAL, UNKNOWN, WARNING

TIMEOUT_HINT = "give seconds, more than 0 and less than a day"


def run_main(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    """Exit code and stdout of `main(argv)`."""
    state = main(list(argv))
    return state, capsys.readouterr().out


def test_version_prints_one_line_and_exits_unknown(capsys: pytest.CaptureFixture[str]) -> None:
    assert run_main(capsys, "-V") == (UNKNOWN, f"check_ros_diagnostics {__version__} (Overseer)\n")


def test_help_documents_every_option_and_exits_unknown(capsys: pytest.CaptureFixture[str]) -> None:
    state, output = run_main(capsys, "--help")
    assert state == UNKNOWN
    for option in (
        "--hostname",
        "--port",
        "--url",
        "--robot",
        "--name",
        "--name-regex",
        "--timeout",
        "--stale-state",
        "--perfdata-values",
        "--authorization",
        "--verbose",
        "--version",
    ):
        assert f" {option}" in output


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([], "UNKNOWN - no robot given: use -r/--robot, or --label for a group (see --help)"),
        (["-r", "robot1", "--bogus"], "UNKNOWN - option --bogus not recognized (see --help)"),
        (["-r", "robot1", "extra"], "UNKNOWN - unexpected argument 'extra' (see --help)"),
        (["-r", "robot1", "-p", "99999"], "UNKNOWN - invalid port '99999': give a number from 1 to 65535"),
        (["-r", "robot1", "-t", "0"], f"UNKNOWN - invalid --timeout '0': {TIMEOUT_HINT}"),
        (["-r", "robot1", "-t", "soon"], f"UNKNOWN - invalid --timeout 'soon': {TIMEOUT_HINT}"),
        (["-r", "robot1", "-t", "nan"], f"UNKNOWN - invalid --timeout 'nan': {TIMEOUT_HINT}"),
        (["-r", "robot1", "-t"], "UNKNOWN - option -t requires a value (see --help)"),
        (["-r", "robot1", "--insecure=yes"], "UNKNOWN - option --insecure takes no value (see --help)"),
        (["-r", "robot1", "-x"], "UNKNOWN - option -x not recognized (see --help)"),
        (
            ["-r", "robot1", "--name-regex=a|("],
            "UNKNOWN - invalid --name-regex 'a¦(': missing ), unterminated subpattern at position 2",
        ),
        (
            ["-r", "robot1", "--stale-state=ok"],
            "UNKNOWN - invalid --stale-state 'ok': use unknown, warning or critical",
        ),
        (
            ["-r", "robot1", "--name-regex=("],
            "UNKNOWN - invalid --name-regex '(': missing ), unterminated subpattern at position 0",
        ),
        (["-r", "robot1", "--url=http://h:1", "-H", "h"], "UNKNOWN - give either --url or -H/-p, not both"),
        (
            ["-r", "robot1", "--url=ftp://h"],
            "UNKNOWN - invalid URL 'ftp://h': it must start with http:// or https://",
        ),
        (
            ["-r", "robot1", "--url=http://u:p@h"],
            "UNKNOWN - invalid URL: give credentials with -a/--authorization, not in the URL",
        ),
    ],
)
def test_usage_errors_are_one_unknown_line(
    capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    assert run_main(capsys, *argv) == (UNKNOWN, message + "\n")


def test_short_and_long_options_mean_the_same() -> None:
    short = options_from_flags(
        *parse_flags(["-H", "10.0.0.2", "-p", "9000", "-r", "a/b", "-n", "bat", "-t", "3", "-vv"])
    )
    long = options_from_flags(
        *parse_flags(
            [
                "--hostname=10.0.0.2",
                "--port=9000",
                "--robot=a/b",
                "--name=bat",
                "--timeout=3",
                "--verbose",
                "--verbose",
            ]
        )
    )
    for options in (short, long):
        assert (options.url, options.robot, options.timeout) == ("http://10.0.0.2:9000", "a/b", 3.0)
        assert (options.settings.name, options.settings.verbosity) == ("bat", 2)


def test_defaults() -> None:
    options = options_from_flags(*parse_flags(["-r", "robot1"]))
    assert (options.url, options.timeout, options.settings.stale_state) == (
        "http://127.0.0.1:9849",
        10.0,
        UNKNOWN,
    )
    assert (options.settings.name, options.settings.name_regex, options.settings.perfdata_values) == (
        "",
        None,
        False,
    )


def test_stale_state_names_ignore_case() -> None:
    for name, state in (("Warning", WARNING), ("CRITICAL", CRITICAL), ("unknown", UNKNOWN)):
        assert (
            options_from_flags(*parse_flags(["-r", "r", f"--stale-state={name}"])).settings.stale_state
            == state
        )


def test_ipv6_hostname_gets_brackets_and_url_loses_its_trailing_slash() -> None:
    assert options_from_flags(*parse_flags(["-r", "r", "-H", "::1"])).url == "http://[::1]:9849"
    assert options_from_flags(*parse_flags(["-r", "r", "--url", "https://o.example/overseer/"])).url == (
        "https://o.example/overseer"
    )


def test_empty_hostname_and_port_fall_back_to_defaults_as_empty_nagios_macros_do() -> None:
    assert (
        options_from_flags(*parse_flags(["-r", "r", "--url=", "-H", "", "-p", ""])).url
        == "http://127.0.0.1:9849"
    )


def test_check_imports_no_json_re_or_typing_only_c_modules_and_its_own() -> None:
    code = (
        "import sys; before = set(sys.modules); import overseer.check;"
        " print(' '.join(sorted(set(sys.modules) - before)))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert set(done.stdout.split()) == {
        "__future__",
        "_json",
        "_socket",
        "overseer",
        "overseer.check",
        "overseer.check.plugin",
        "overseer.client",
        "overseer.client.exporter",
        "overseer.client.http",
        "overseer.severity",
        "overseer.check.api_reader",
        "overseer.check.document",
        "overseer.verdict",
    }


def test_short_options_cluster_and_take_attached_or_separate_values() -> None:
    flags, verbosity = parse_flags(["-vvrrobot1", "-n", "-odd name", "--name-regex", "x"])
    assert flags == {"--verbose": "", "--robot": "robot1", "--name": "-odd name", "--name-regex": "x"}
    assert verbosity == 2
