"""The name of a ROS 1 robot known only by its master: the master's host, in the exporter and the check alike.

It imports nothing: `check_ros_diagnostics --ros-master` loads it at start.
"""


def master_host(master_uri: str) -> str:
    """The host of a ROS master URI, e.g. `10.0.0.5` of `http://10.0.0.5:11311`."""
    netloc = master_uri.partition("://")[2] or master_uri
    host = netloc.partition("/")[0]
    if host.startswith("["):  # [::1]:11311
        return host[1:].partition("]")[0]
    return host.rpartition(":")[0] if ":" in host else host
