"""Node factories take rclpy's keywords and refuse misspelt ones (no silent **kwargs)."""
import pytest


def test_misspelt_keyword_is_an_error(router_env):
    import roszen
    node = roszen.Node("strict_factories")
    try:
        node.create_publisher("std_msgs/msg/String", "/strict", 10, callback_group=None)
        node.create_timer(1.0, lambda: None, callback_group=None)
        with pytest.raises(TypeError):
            node.create_publisher("std_msgs/msg/String", "/strict", 10, qos_profle=5)
        with pytest.raises(TypeError):
            node.create_subscription("std_msgs/msg/String", "/strict", print, 10, rawx=True)
        with pytest.raises(TypeError):
            node.create_service("std_srvs/srv/Trigger", "/strict_srv", print, callbackgroup=None)
        with pytest.raises(TypeError):
            node.create_client("std_srvs/srv/Trigger", "/strict_srv", qos=1)
        with pytest.raises(TypeError):
            node.create_timer(1.0, print, period=2)
    finally:
        node.destroy_node()
