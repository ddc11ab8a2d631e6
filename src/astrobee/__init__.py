"""The transport-free core every Astrobee package shares: config, scenario, rotations, flight
modes and message conversions. Importing it (or any of its modules) loads no zenoh and no node
machinery; the ROS edge lives in the node packages' *_node.py modules and in roszen."""
