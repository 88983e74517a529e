"""ROS 1 robots: XML-RPC to each robot's master, TCPROS to its publishers; no ROS installation needed."""
