"""A node that publishes /clock to itself as fast as it can (as sim_node does in lockstep) and
spins between publishes: most of its main thread's time is spent inside zenoh puts that run its
own /clock callback, where a default SIGINT would land and be swallowed. Started through
roszen.node_main.run like the project's nodes; prints 'looping' once running."""
import sys

from roszen import QoSProfile, message_class, node_main
from roszen.node import Node


class ClockLoop:
    def __init__(self, argv):
        self.node = Node("clock_loop", argv=[*argv, "--ros-args", "-p", "use_sim_time:=true"])
        self.Clock = message_class("rosgraph_msgs/msg/Clock")
        self.pub = self.node.create_publisher("rosgraph_msgs/msg/Clock", "/clock",
                                              QoSProfile(depth=1))

    def spin(self):
        ns = 0
        print("looping", flush=True)
        while self.node._alive:
            ns += 1_000_000
            msg = self.Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(ns, 1_000_000_000)
            self.pub.publish(msg)
            self.node.spin_once(timeout_sec=0)

    def close(self):
        self.node.destroy_node()


if __name__ == "__main__":
    if "--default-sigint" in sys.argv:      # the old behaviour, for comparison by hand
        node_main._install_sigint = lambda: None
    sys.exit(node_main.run(ClockLoop, [a for a in sys.argv if a != "--default-sigint"]))
