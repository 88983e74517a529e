"""The one severity order: of ROS levels and Nagios states alike, which share their numbers.

OK=0 (OK), WARN=1 (WARNING), ERROR=2 (CRITICAL), STALE=3 (UNKNOWN), ranked ERROR > WARN > STALE > OK, as
Nagios ranks CRITICAL > WARNING > UNKNOWN > OK: a plain numeric maximum would rank a stale robot worse than
a failing one. Standard library only, and nothing to import: the check starts once per check.
"""

# The rank of each level (state) by its number: higher is worse.
SEVERITY_RANK = (0, 2, 3, 1)
WORST_RANK = 3
