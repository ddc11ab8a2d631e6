"""The rcl_interfaces parameter services (~/get_parameters ...) so `ros2 param` works."""
from __future__ import annotations

from . import codec


class ParameterServices:
    """Placeholder until filled in: raises TypeSupportError when the .srv types are missing."""

    def __init__(self, node) -> None:
        codec.srv_support("rcl_interfaces/srv/GetParameters")
        self.node = node
