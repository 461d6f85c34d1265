"""ROS 2 without ROS: the robot's topics in CDR on Zenoh, commands from ROS 2 in, runs exported as ROS 2 bags.

What lives here (docs/ros2.md):

* :mod:`~beastbt.ros2.cdr`: the ROS 2 messages beastbt speaks, written and read as little-endian CDR by
  hand (struct and numpy), byte for byte what a ROS 2 node sends; their type names and RIHS01 hashes.
* :mod:`~beastbt.ros2.rmw_zenoh`: rmw_zenoh's key expressions, liveliness tokens and attachments, pinned
  to one version of rmw_zenoh_cpp.
* :mod:`~beastbt.ros2.bridge`: zenoh-bridge-ros2dds's plain keys (a ROS 2 on DDS, Humble's default).
* :mod:`~beastbt.ros2.topics`: what a run publishes, from what the run has (odometry, tf, scan, map...).
* :mod:`~beastbt.ros2.link`: the link itself: a Zenoh session, the publishers, the inputs into the run.
* :mod:`~beastbt.ros2.bag`: ``beastbt export RUN --ros2 out.mcap``.

No ROS install is needed on the robot; nothing here is imported unless ``--ros2`` or the export asks for it.
"""
