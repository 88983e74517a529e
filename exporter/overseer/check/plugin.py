"""check_ros_diagnostics: a Monitoring Plugins check of one robot (or a group by label) from the JSON API.

It starts once per check, so it imports only cheap standard modules (no argparse or getopt; a socket
rather than urllib: see `overseer.client.http`) and none of the exporter; bench/bench_check.py measures it.
"""

from __future__ import annotations

import sys

from overseer import __version__
from overseer.check import api_reader
from overseer.check.document import CheckError, robot_from_document
from overseer.client.exporter import ExporterClient, credentials, exporter_url, timeout_seconds
from overseer.client.http import Answer, ClientError, Tls
from overseer.verdict import CRITICAL, UNKNOWN, WARNING, Settings, clean, judge, plugin_output

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing (14 ms)
if TYPE_CHECKING:
    import re

PROGRAM = "check_ros_diagnostics"
ROBOTS_PATH = "/api/v1/robots"

USAGE = f"""Usage:
 {PROGRAM} [-H <exporter host>] [-p <port>] | [--url <exporter URL>]  -r <robot>
   [-n <text>] [--name-regex <regex>] [--stale-state unknown|warning|critical] [--perfdata-values]
   [--authorization-file <file> | -a <user:password>] [--ca-file <file>] [--insecure]
   [--client-cert <file> [--client-key <file>]] [-t <seconds>] [-v] [-V] [-h]
 {PROGRAM} [-H <exporter host>] [-p <port>] | [--url <exporter URL>]  --label <name=value> [--label ...]
   [--stale-state unknown|warning|critical] [...]
 {PROGRAM} --ros-master <ROS 1 master URL> [--ros-topic diagnostics_agg|diagnostics] [-r <robot>] [...]"""

HELP = f"""{PROGRAM} {__version__} (Overseer)
Checks one ROS robot's diagnostics as the Overseer exporter sees them (its JSON API, so the same
data Prometheus scrapes): the worst component state, per-level counts as perfdata, and the list of
components per state.

{USAGE}

Options:
 -h, --help
    Print this help and exit (with 3, UNKNOWN, as the Monitoring Plugins do)
 -V, --version
    Print the version and exit (with 3, UNKNOWN)
 -H, --hostname=ADDRESS
    Host name or IP address of the Overseer exporter, not of the robot (default: 127.0.0.1)
 -p, --port=INTEGER
    Port of the exporter (default: 9849)
 --url=URL
    Base URL of the exporter instead of -H/-p, e.g. https://overseer.example:9849 or a proxy path
 -r, --robot=NAME
    The robot as the exporter names it (its ROS namespace, e.g. robot1 or site_a/robot7). With
    --ros-master it defaults to the master's host (10.0.0.5), as `overseer run --ros-master` names it
 --label=NAME=VALUE
    Without -r: judge every robot the exporter's inventory gives this label (e.g. site=site_a), as one
    group: the worst robot's state, the robots listed by state; repeat to ask for several labels
 --ros-master=URL
    No exporter: read one message straight from a ROS 1 robot's master and publisher, as the
    paper's plugin did (e.g. http://10.0.0.5:11311); same output, waits at most --timeout
 --ros-topic=TOPIC
    With --ros-master: diagnostics_agg (default) or diagnostics
 -n, --name=TEXT
    Judge only components whose name contains TEXT, ignoring case (e.g. battery); empty: all
 --name-regex=REGEX
    Judge only components whose name matches the Python regular expression REGEX (with -n: both)
 --stale-state=STATE
    State for stale components and for a robot that is down: unknown (default), warning, critical
 --perfdata-values
    Add the numeric key-values of the judged components to the perfdata ('<component>:<key>')
 --authorization-file=FILE
    Basic authentication: FILE's first line is USER:PASSWORD (make it readable by the monitoring user
    only). Without it or -a, the environment variable CHECK_ROS_DIAGNOSTICS_AUTH=USER:PASSWORD is used
 -a, --authorization=USER:PASSWORD
    Basic authentication on the command line. Other users of the host can read command lines (ps,
    /proc): prefer --authorization-file or CHECK_ROS_DIAGNOSTICS_AUTH
 --ca-file=FILE
    CA certificates to verify an https exporter with (default: the system's)
 --insecure
    Do not verify the https exporter's certificate
 --client-cert=FILE
    Client certificate (PEM) for an exporter that requires one (mutual TLS); FILE may hold the key too
 --client-key=FILE
    The client certificate's key, when it is in a file of its own
 -t, --timeout=SECONDS
    Give up after SECONDS, with UNKNOWN (default: 10)
 -v, --verbose
    Once: add each component's key-values to the lists; twice: also the URL that was read

States: a component in ERROR is CRITICAL, in WARN is WARNING, in OK is OK; a stale one (and a robot
that is down) is UNKNOWN unless --stale-state says otherwise. The check's state is the worst one by
CRITICAL > WARNING > UNKNOWN > OK. Unreachable exporter, timeout, HTTP or authentication errors,
malformed answers, unknown robots and a filter that matches nothing are UNKNOWN, each with its reason.

Example:
 {PROGRAM} -H 127.0.0.1 -r robot1 -n battery
 WARNING - robot1: /Power/Robot Battery (Low charge) | 'error'=0;;;0 'warn'=1;;;0 'stale'=0;;;0 'ok'=1;;;0"""

# Long option → whether it takes a value; the short options are aliases.
LONG_OPTIONS = {
    "--help": False,
    "--version": False,
    "--hostname": True,
    "--port": True,
    "--url": True,
    "--robot": True,
    "--name": True,
    "--name-regex": True,
    "--stale-state": True,
    "--perfdata-values": False,
    "--authorization": True,
    "--authorization-file": True,
    "--ca-file": True,
    "--insecure": False,
    "--client-cert": True,
    "--client-key": True,
    "--timeout": True,
    "--verbose": False,
    "--ros-master": True,
    "--ros-topic": True,
    "--label": True,
}
REPEATABLE = "--label"  # its values are kept, joined by a NUL, not replaced
_SHORT_OPTIONS = {
    "-h": "--help",
    "-V": "--version",
    "-H": "--hostname",
    "-p": "--port",
    "-r": "--robot",
    "-n": "--name",
    "-a": "--authorization",
    "-t": "--timeout",
    "-v": "--verbose",
}
_STALE_STATES = {"unknown": UNKNOWN, "warning": WARNING, "critical": CRITICAL}


class Options:
    """What the command line asks for."""

    __slots__ = (
        "authorization",
        "labels",
        "robot",
        "ros_master",
        "ros_topic",
        "settings",
        "timeout",
        "tls",
        "url",
    )

    def __init__(
        self,
        url: str,
        robot: str,
        settings: Settings,
        timeout: float,
        authorization: str,
        tls: Tls,
        ros_master: str = "",
        ros_topic: str = "diagnostics_agg",
        labels: tuple[str, ...] = (),
    ) -> None:
        """Keep the fields; `url` is the exporter's base URL without a trailing '/', '' with `ros_master`.

        `labels` (NAME=VALUE) choose a group of robots to judge instead of `robot` ('' then).
        """
        self.url = url
        self.labels = labels
        self.robot = robot
        self.settings = settings
        self.timeout = timeout
        self.authorization = authorization
        self.tls = tls
        self.ros_master = ros_master
        self.ros_topic = ros_topic


def main(argv: list[str] | None = None) -> int:
    """Run the check on `argv` (default: the command line), print its output, return the exit code."""
    try:
        state, text = outcome(sys.argv[1:] if argv is None else argv)
    except (CheckError, ClientError) as error:
        state, text = UNKNOWN, f"UNKNOWN - {clean(str(error))}"
    except Exception as error:  # a plugin never dies with a traceback: Nagios would show only its last line
        state, text = UNKNOWN, f"UNKNOWN - internal error: {type(error).__name__}: {clean(str(error))}"
    sys.stdout.buffer.write(text.encode("utf-8", "replace") + b"\n")
    sys.stdout.flush()
    return state


def outcome(argv: list[str]) -> tuple[int, str]:
    """The exit state and output for `argv`: help, version, or the check's result."""
    flags, verbosity = parse_flags(argv)
    if "--help" in flags:
        return UNKNOWN, HELP
    if "--version" in flags:
        return UNKNOWN, f"{PROGRAM} {__version__} (Overseer)"
    return check(options_from_flags(flags, verbosity))


def parse_flags(argv: list[str]) -> tuple[dict[str, str], int]:
    """The options given, by long name (the last one wins), and how many times -v was given.

    GNU getopt_long style (`--name=value`, `--name value`, `-n value`, `-nvalue`, `-vv`), written out
    because the getopt module imports gettext, which costs more than this.
    """
    flags: dict[str, str] = {}
    verbosity = 0
    pending = argv[::-1]
    while pending:
        for name, value in split_argument(pending.pop(), pending):
            flags[name] = flags[name] + "\0" + value if name == REPEATABLE and name in flags else value
            if name == "--verbose":
                verbosity += 1
    return flags, verbosity


def split_argument(argument: str, pending: list[str]) -> list[tuple[str, str]]:
    """The (long option, value) pairs in one argument; a value given separately is popped off `pending`."""
    if argument.startswith("--"):
        name, equals, value = argument.partition("=")
        if name not in LONG_OPTIONS:
            raise CheckError(f"option {name} not recognized (see --help)")
        if equals and not LONG_OPTIONS[name]:
            raise CheckError(f"option {name} takes no value (see --help)")
        return [(name, value if equals or not LONG_OPTIONS[name] else next_value(name, pending))]
    if len(argument) < 2 or not argument.startswith("-"):
        raise CheckError(f"unexpected argument {argument!r} (see --help)")
    pairs: list[tuple[str, str]] = []
    for index, letter in enumerate(argument[1:], start=2):
        name = _SHORT_OPTIONS.get(f"-{letter}", "")
        if not name:
            raise CheckError(f"option -{letter} not recognized (see --help)")
        if LONG_OPTIONS[name]:
            return [*pairs, (name, argument[index:] or next_value(f"-{letter}", pending))]
        pairs.append((name, ""))
    return pairs


def next_value(option: str, pending: list[str]) -> str:
    """The separate value of `option`, popped off `pending`."""
    if not pending:
        raise CheckError(f"option {option} requires a value (see --help)")
    return pending.pop()


def options_from_flags(flags: dict[str, str], verbosity: int) -> Options:
    """Validated options; CheckError naming the first bad one."""
    robot = flags.get("--robot", "")
    labels = tuple(flags["--label"].split("\0")) if "--label" in flags else ()
    if not robot and flags.get("--ros-master"):
        from overseer.ros_master import master_host

        robot = master_host(flags["--ros-master"])
    if labels:
        check_group_flags(flags, labels)
    elif not robot:
        raise CheckError("no robot given: use -r/--robot, or --label for a group (see --help)")
    settings = Settings(
        name=flags.get("--name", ""),
        name_regex=compile_regex(flags.get("--name-regex", "")),
        stale_state=stale_state(flags.get("--stale-state", "unknown")),
        perfdata_values="--perfdata-values" in flags,
        verbosity=verbosity,
    )
    ros_master = flags.get("--ros-master", "")
    if ros_master and ("--url" in flags or "--hostname" in flags or "--port" in flags):
        raise CheckError("give either --ros-master or the exporter's address (--url, -H/-p), not both")
    ros_topic = flags.get("--ros-topic", "diagnostics_agg")
    if ros_topic not in ("diagnostics_agg", "diagnostics"):
        raise CheckError(f"invalid --ros-topic {ros_topic!r}: use diagnostics_agg or diagnostics")
    exporter = (
        "" if ros_master else exporter_url(*(flags.get(f, "") for f in ("--url", "--hostname", "--port")))
    )
    return Options(
        url=exporter,
        robot=robot,
        settings=settings,
        timeout=timeout_seconds(flags.get("--timeout", "10")),
        authorization=credentials(flags.get("--authorization-file", ""), flags.get("--authorization", "")),
        tls=Tls(
            ca_file=flags.get("--ca-file", ""),
            insecure="--insecure" in flags,
            client_cert=flags.get("--client-cert", ""),
            client_key=flags.get("--client-key", ""),
        ),
        ros_master=ros_master,
        ros_topic=ros_topic,
        labels=labels,
    )


def check_group_flags(flags: dict[str, str], labels: tuple[str, ...]) -> None:
    """CheckError when `--label` is given with what only judges one robot, or a label is not NAME=VALUE."""
    for label in labels:
        name, equals, _ = label.partition("=")
        if not equals or not name:
            raise CheckError(f"invalid --label {label!r}: use NAME=VALUE, e.g. site=site_a")
    one_robot = ("--robot", "--name", "--name-regex", "--perfdata-values", "--ros-master")
    given = [flag for flag in one_robot if flag in flags]
    if given:
        raise CheckError(f"--label judges a group of robots, not their components: drop {', '.join(given)}")


def compile_regex(pattern: str) -> re.Pattern[str] | None:
    """The compiled --name-regex, None when not given; CheckError when it is not a valid expression."""
    if not pattern:
        return None
    import re  # only a --name-regex pays for it

    try:
        return re.compile(pattern)
    except re.error as error:
        raise CheckError(f"invalid --name-regex {pattern!r}: {error}") from None


def stale_state(name: str) -> int:
    """The Nagios state --stale-state names."""
    try:
        return _STALE_STATES[name.lower()]
    except KeyError:
        raise CheckError(f"invalid --stale-state {name!r}: use unknown, warning or critical") from None


def check(options: Options) -> tuple[int, str]:
    """Read the robot from the exporter (or straight from its ROS 1 master) and judge it."""
    settings = options.settings
    if options.ros_master:
        verdict = judge(robot_from_document(read_from_master(options)), settings)
        return verdict.state, plugin_output(verdict, settings.verbosity)
    client = ExporterClient(
        options.url, options.timeout, options.authorization, options.tls, f"{PROGRAM}/{__version__}"
    )
    if options.labels:
        return check_group(client, options)
    url = client.url_of(ROBOTS_PATH, options.robot)
    answer = client.get(ROBOTS_PATH, options.robot)
    check_status(answer, url, options)
    try:
        document = api_reader.loads(answer.body)
    except ValueError as error:
        raise CheckError(f"malformed JSON from {url}: {error}") from None
    try:
        robot = robot_from_document(document)
    except CheckError as error:
        raise CheckError(f"unexpected answer from {url}: {error}") from None
    verdict = judge(robot, settings)
    text = plugin_output(verdict, settings.verbosity)
    if settings.verbosity > 1:
        text += f"\nRead {url} (HTTP {answer.status}, {len(answer.body)} bytes)"
    return verdict.state, text


def check_group(client: ExporterClient, options: Options) -> tuple[int, str]:
    """Read the robots carrying every label asked for and judge them as one group."""
    from urllib.parse import quote  # only a group check pays for these

    from overseer.check.group import judge_group, summaries_from_document

    query = "&".join("label=" + quote(label, safe="=") for label in options.labels)
    url = client.url_of(ROBOTS_PATH) + "?" + query
    answer = client.get(ROBOTS_PATH + "?" + query)
    check_status(answer, url, options)
    try:
        robots, generated_at = summaries_from_document(api_reader.loads(answer.body))
    except ValueError as error:
        raise CheckError(f"malformed JSON from {url}: {error}") from None
    except CheckError as error:
        raise CheckError(f"unexpected answer from {url}: {error}") from None
    verdict = judge_group(robots, ", ".join(options.labels), options.settings.stale_state, generated_at)
    text = plugin_output(verdict, options.settings.verbosity)
    if options.settings.verbosity > 1:
        text += f"\nRead {url} (HTTP {answer.status}, {len(answer.body)} bytes)"
    return verdict.state, text


def read_from_master(options: Options) -> dict[str, object]:
    """The robot's API document built from one message read directly from its ROS 1 master."""
    from overseer.check.ros1_direct import Ros1DirectError, read_robot_document  # only this mode pays for it

    try:
        return read_robot_document(
            options.ros_master, options.robot, options.timeout, topic=options.ros_topic
        )
    except Ros1DirectError as error:
        raise CheckError(str(error)) from None


def check_status(answer: Answer, url: str, options: Options) -> None:
    """CheckError unless the answer is a 200; an exporter's 404 means it does not know the robot."""
    if answer.status == 200:
        return
    if answer.status in (401, 403):
        raise CheckError(f"authentication refused by {url}: HTTP {answer.status} {answer.reason}")
    if answer.status == 404 and is_exporter_error(answer.body):
        raise CheckError(
            f"{clean(options.robot)} is unknown to the exporter at {options.url}"
            " (never discovered, or forgotten after expire_after)"
        )
    raise CheckError(f"HTTP {answer.status} {answer.reason} from {url}")


def is_exporter_error(body: bytes) -> bool:
    """Whether `body` is the exporter's JSON error document ({"error": ...})."""
    try:
        document = api_reader.loads(body)
    except ValueError:
        return False
    return isinstance(document, dict) and "error" in document
