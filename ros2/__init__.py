"""The monitor on a robot's own ROS 2 bus, with no ROS installation: the ROS 2 messages as
Cyclone DDS types generated from ``rosbags``' definitions (``ros2.messages``), and the DDS
domain joined as ROS's own environment says, with ROS 2's topic names and QoS (``ros2.bus``).

Needs the optional extra: ``pip install 'neural-asm[ros2]'`` (Eclipse Cyclone DDS, the DDS
implementation behind ``rmw_cyclonedds_cpp``).
"""
