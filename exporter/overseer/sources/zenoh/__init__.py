"""ROS 2 robots over Zenoh: rmw_zenoh's keys and liveliness tokens, and zenoh-bridge-ros2dds' keys."""
