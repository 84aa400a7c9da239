"""A robot's own logs as skill-memory data: ROS 2 bags (rosbag2 MCAP) and LeRobot datasets,
turned into the project's sequences by a channel mapping file (``logs.mapping``)."""
