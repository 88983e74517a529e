"""ROS 2 robots over DDS: Cyclone DDS joins their domains and reads their diagnostics topics raw."""
