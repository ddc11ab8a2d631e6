"""A stand-in for sim_node in lockstep, for the sim-time recording tests: publishes /clock and
/tick (std_msgs/Int32: the sim time in ms) every 100 ms of sim time, 5 times faster than the
wall clock; after `n` ticks the clock restarts at 0 (a sim reset) for `n // 2` more ticks, then
it prints 'done' and idles until stopped. Waits for a /tick subscriber before starting."""
import sys
import time


def main() -> int:
    from roszen import CLOCK, Node, message_class
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    node = Node("fake_lockstep")
    Clock, Int32 = message_class("rosgraph_msgs/msg/Clock"), message_class("std_msgs/msg/Int32")
    clock = node.create_publisher("rosgraph_msgs/msg/Clock", "/clock", CLOCK)
    tick = node.create_publisher("std_msgs/msg/Int32", "/tick", 100)
    print("waiting", flush=True)
    while tick.get_subscription_count() < 1 or clock.get_subscription_count() < 1:
        time.sleep(0.05)
    time.sleep(0.5)
    for count in (n, n // 2):
        for k in range(1, count + 1):
            ms = 100 * k
            c = Clock()
            c.clock.sec, c.clock.nanosec = divmod(ms * 1_000_000, 1_000_000_000)
            clock.publish(c)
            tick.publish(Int32(data=ms))
            time.sleep(0.02)
    print("done", flush=True)
    try:
        while True:
            time.sleep(0.1)
    except KeyboardInterrupt:
        pass
    node.destroy_node()
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit(0)
