"""Test-wide settings."""

import os

# Every message published under inproc is checked as rclpy's setters would check it, so that node
# code passing here also runs on a real ROS 2 install (see gait_nodes.interfaces.validate_message).
os.environ.setdefault('GAIT_NODES_STRICT_MESSAGES', '1')
