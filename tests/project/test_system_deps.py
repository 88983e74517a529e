"""scripts/install-system-deps: every program the tests run is there, and a second run installs nothing, fast.

`make test` runs the script before the tests, so a program missing here is a package missing from its list.
"""

from __future__ import annotations

import shutil
import subprocess
import time

import pytest

from testbed.paths import REPO

pytestmark = pytest.mark.servers  # needs the test packages, as the tests of real servers do (not test-quick)

# Every program the tests and the testbed start, by the name or path they use.
PROGRAMS = [
    "ip",  # iproute2: network namespaces for the fault and unicast-DDS tests
    "ss",  # iproute2: sockets inside a namespace
    "nsenter",  # util-linux: commands inside a namespace
    "mount",  # the read-only tmpfs of the event store's test
    "umount",
    "git",  # the standalone test lists the tracked files
    "openssl",
    "promtool",
    "amtool",
    "prometheus",
    "prometheus-alertmanager",
    "chromium",
    "cmake",  # the Fast DDS publisher's build, with make, g++ and fastddsgen
    "make",
    "g++",
    "fastddsgen",
    "gcc",  # the compiled status decoder
    "/usr/sbin/icinga2",
    "/usr/sbin/nagios4",
    "/usr/bin/rosmaster",
    "/usr/bin/python3",  # Debian's, for ROS 1's rospy
    "faketime",  # libfaketime, which steps a running exporter's wall clock
]


@pytest.mark.parametrize("program", PROGRAMS)
def test_every_program_the_tests_run_is_installed(program: str) -> None:
    assert shutil.which(program), f"{program} is missing: scripts/install-system-deps test should install it"


def test_a_second_run_installs_nothing_and_is_fast() -> None:
    started = time.monotonic()
    done = subprocess.run(
        [str(REPO / "scripts" / "install-system-deps"), "test"], capture_output=True, text=True, timeout=60
    )
    assert (done.returncode, done.stdout, done.stderr) == (0, "", "")
    assert time.monotonic() - started < 2.0


def test_it_refuses_an_unknown_target() -> None:
    done = subprocess.run(
        [str(REPO / "scripts" / "install-system-deps"), "everything"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert "usage" in done.stderr
