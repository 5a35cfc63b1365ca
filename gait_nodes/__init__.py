"""gait_nodes: online walking-gait generation as a ROS 2 node suite (rclpy, dds or inproc)."""
