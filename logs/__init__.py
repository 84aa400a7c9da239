"""A robot's own logs as skill-memory data: ROS 2 bags (MCAP or sqlite3), ROS 1 bags and LeRobot
datasets, turned into the project's sequences by a channel mapping file (``logs.mapping``).
Readers only: streaming them to a service is the client's (``client/replay.py``)."""
