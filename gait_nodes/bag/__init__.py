"""rosbag2 (MCAP storage) files: writing (:mod:`.writer`); no ROS import here."""
