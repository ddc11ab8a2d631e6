"""A tiny node of ours for the CLI tests: serves /add_two_ints (example_interfaces/AddTwoInts)
and /trigger (std_srvs/Trigger), publishes /adder/count (std_msgs/Int32) at 10 Hz and a
latched /adder/mode (std_msgs/String); parameters `increment` (int, the count's step), `label`
(string), `gain` (double), `weights` (double array) for `param` verbs."""
import sys


def main() -> int:
    from roszen import LATCHED, Node, ParameterDescriptor, message_class
    node = Node("adder", argv=sys.argv)
    calls = [0]

    def add(req, resp):
        resp.sum = req.a + req.b
        calls[0] += 1
        return resp

    def trigger(req, resp):
        resp.success = True
        resp.message = f"triggered after {calls[0]} additions"
        return resp

    node.create_service("example_interfaces/srv/AddTwoInts", "/add_two_ints", add)
    node.create_service("std_srvs/srv/Trigger", "/trigger", trigger)
    Int32, String = message_class("std_msgs/msg/Int32"), message_class("std_msgs/msg/String")
    count_pub = node.create_publisher("std_msgs/msg/Int32", "/adder/count", 10)
    mode = node.create_publisher("std_msgs/msg/String", "/adder/mode", LATCHED)
    mode.publish(String(data="adding"))
    node.declare_parameter("increment", 1)
    node.declare_parameter("label", "adder")
    node.declare_parameter("gain", 0.5, ParameterDescriptor(description="a scale", min_value=0.0,
                                                            max_value=10.0))
    node.declare_parameter("weights", [1.0, 2.0])
    n = [0]

    def tick():
        n[0] += node.get_parameter("increment").value
        count_pub.publish(Int32(data=n[0]))

    node.create_timer(0.1, tick)
    print("adder ready", flush=True)
    try:
        node.spin()
    except KeyboardInterrupt:
        pass
    node.destroy_node()
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:      # stopped while starting: quietly, as the project's nodes do
        sys.exit(0)
