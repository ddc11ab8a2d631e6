"""CBF safety filter: the algorithm, free of transport.

    from astrobee_control.safety import SafetyFilter, SafetyResult, BodySphere
    filt = SafetyFilter(flight_modes.get("nominal"), mass.robot())
    res = filt.filter(force_body, torque_body, state, extent=box_corners(offset, size))

LawFilter (law_filter.py) is one robot's filter as a control loop uses it: the carried bag,
counters and diagnostics; safety_filter_node, controller_node (safety:=true) and Flight use it.
"""
from .filter import SafetyFilter, SafetyResult
from .geometry import BodySphere, box_corners, box_sphere, corridor_boxes, robot_sphere
from .law_filter import LawFilter
from .load import carried_load

__all__ = ["SafetyFilter", "SafetyResult", "BodySphere", "box_corners", "box_sphere",
           "corridor_boxes", "robot_sphere", "carried_load", "LawFilter"]
