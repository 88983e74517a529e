"""ROS 2 robots through rclpy: the exporter as a ROS 2 node on whatever RMW the installation has."""
