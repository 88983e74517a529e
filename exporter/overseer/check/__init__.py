"""check_ros_diagnostics: the Nagios-compatible check, reading the exporter's JSON API or a ROS 1 robot.

Kept light on purpose: Nagios and Icinga start it for every check, so it imports no `re`, `json` or
`typing` (see `tests/check/test_check_cli.py`).
"""

from overseer.check.plugin import main

__all__ = ["main"]
