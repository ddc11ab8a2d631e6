"""CBF safety filter (issue 16): the algorithm, free of transport.

    from astrobee_control.safety import SafetyFilter, SafetyResult, BodySphere
    filt = SafetyFilter(flight_modes.get("nominal"), mass.robot())
    res = filt.filter(force_body, torque_body, state, extent=box_corners(offset, size))
"""
from .filter import SafetyFilter, SafetyResult
from .geometry import BodySphere, box_corners, box_sphere, corridor_boxes, robot_sphere
from .load import carried_load

__all__ = ["SafetyFilter", "SafetyResult", "BodySphere", "box_corners", "box_sphere",
           "corridor_boxes", "robot_sphere", "carried_load"]
