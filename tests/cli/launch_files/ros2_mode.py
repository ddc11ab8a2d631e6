"""Test launch description: one node by package/executable, plus the router, to see which
command lines the launcher uses when a ROS 2 install with rmw_zenoh is detected."""
from astrobee_bringup.process_group import NodeSpec


def generate_nodes(ctx):
    return [
        NodeSpec("router", kind="router", command=["router", "--port", str(ctx.port)],
                 ros2_command=["ros2", "run", "rmw_zenoh_cpp", "rmw_zenohd"]),
        NodeSpec("talker", "demo_nodes_py", "talker", parameters=[{"x": 1, "flag": True}],
                 ros_args=["-r", "chatter:=/talk"]),
    ]
