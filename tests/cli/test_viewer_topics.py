"""A recording every viewer shows whole: sim_node publishes the cargo bag's surface
as a visualization_msgs/Marker TRIANGLE_LIST (/sim/bag/marker, at the mesh rate), the robot's
URDF on latched /robot_description and its boxes on latched /sim/robot_markers (the module
labels are in /sim/markers);
every topic of a recorded graph run decodes with mcap-ros2-support (standard or shipped
schemas only)."""
from __future__ import annotations

import signal
import sys

import numpy as np
import pytest

from conftest import ASTROBEE, graph_env   # at import time: "conftest" is another folder's later


def _rosmsg(name):
    import roszen
    return roszen.message_class(name)


@pytest.mark.parametrize("model", ["rigid", "fem"])
def test_marker_bytes_are_the_serialised_marker(model):
    """BagSurface.payload (what sim_node publishes, spliced CDR) == serialize(marker)."""
    from roszen import codec

    from astrobee_sim import markers
    from astrobee_sim.bags.mesh import bag_mesh

    class Bag:
        pass
    bag = Bag()
    bag.model = model
    if model == "fem":
        bag.mesh = bag_mesh(np.array([0.5, 0.35, 0.25]), [np.array([1.0, 0.0, 0.0])], 200)
        pts = bag.mesh.nodes + np.array([10.0, -2.0, 4.8])
    else:
        pts = np.random.default_rng(1).random((8, 3))
    header = _rosmsg("std_msgs/msg/Header")()
    header.stamp.sec, header.stamp.nanosec = 12, 345
    surface = markers.BagSurface(_rosmsg("visualization_msgs/msg/Marker"),
                                 _rosmsg("geometry_msgs/msg/Point"))
    sup = codec.msg_support("visualization_msgs/msg/Marker")
    m = surface.marker(bag, pts, header)
    assert m.type == 11 and len(m.points) % 3 == 0 and len(m.points) >= 36
    assert surface.payload(bag, pts, header, sup.serialize) == sup.serialize(m)
    back = sup.deserialize(surface.payload(bag, pts, header, sup.serialize))
    assert back.header.stamp.sec == 12 and back.header.frame_id == "world"
    assert back.ns == "cargo_bag" and len(back.points) == len(m.points)
    used = np.array([[p.x, p.y, p.z] for p in back.points])
    # every triangle vertex is one of the bag's points (no made-up geometry)
    assert all(np.min(np.linalg.norm(pts - v, axis=1)) < 1e-12 for v in used)


def test_urdf_is_the_sims_astrobee():
    from astrobee_sim import markers
    text = markers.robot_description()
    assert text.startswith('<?xml version="1.0"?><robot name="astrobee">')
    assert '<link name="body">' in text and 'name="arm_proximal_joint"' in text


@pytest.mark.graph
def test_recorded_run_decodes_whole_with_mcap_ros2(procs, port, tmp_path):
    """A short graph run with the FEM cargo bag (no mission: stopped by Ctrl-C once the viewer
    topics are recorded): every message decodes with mcap-ros2-support."""
    run = tmp_path / "run"
    p = procs([ASTROBEE, "launch", "cargo_transport", "scenario:=node2_to_jem_bag",
               "bag_model:=fem", "fem_solver:=fast", "bag_resolution:=200", "mission:=false",
               "--port", str(port), "--run-dir", str(run)], env=graph_env(port))
    for topic in ("/sim/bag/marker", "/robot_description", "/sim/markers", "/sim/robot_markers"):
        p.wait_line(f"Subscribed to topic '{topic}'", timeout=180)
    p.wait_line("pd controller up", timeout=120)
    import time
    time.sleep(3.0)
    p.signal(signal.SIGINT)
    assert p.wait(timeout=90) == 0, p.lines[-15:]

    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    msgs: dict[str, list] = {}
    (path,) = (run / "bag").glob("*.mcap")
    with open(path, "rb") as f:
        for m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            msgs.setdefault(m.channel.topic, []).append(m.decoded_message)
    assert {"/sim/bag/marker", "/robot_description", "/sim/markers", "/sim/robot_markers", "/tf",
            "/loc/truth/pose", "/sim/bag/state"} <= set(msgs), sorted(msgs)
    bag = msgs["/sim/bag/marker"][-1]
    assert bag.type == 11 and bag.header.frame_id == "world" and len(bag.points) % 3 == 0
    centre = msgs["/sim/bag/state"][-1].pose.position
    pts = np.array([[q.x, q.y, q.z] for q in bag.points])
    assert np.linalg.norm(pts.mean(axis=0) - [centre.x, centre.y, centre.z]) < 0.3
    assert msgs["/robot_description"][0].data.startswith("<?xml")
    robot = msgs["/sim/robot_markers"][-1].markers
    assert len(robot) == 3 and all(m.ns == "robot" and m.header.frame_id == "body" for m in robot)
    arr = msgs["/sim/markers"][-1].markers
    assert any(m.ns == "modules" and m.type == 9 and m.text for m in arr)   # labels
    check_layout_against(msgs)         # docs/foxglove_layout.json shows what a run holds


def layout_paths() -> list[str]:
    """Every message path the Foxglove layout (docs/foxglove_layout.json) plots or shows."""
    import json
    from pathlib import Path
    layout = json.loads((Path(__file__).resolve().parents[2] / "docs" /
                         "foxglove_layout.json").read_text())
    leaves: list[str] = []

    def walk(node):
        if isinstance(node, str):
            leaves.append(node)
        else:
            walk(node["first"])
            walk(node["second"])
    walk(layout["layout"])
    assert set(leaves) == set(layout["configById"])        # every panel placed, none missing
    paths = []
    for cfg in layout["configById"].values():
        paths += [p["value"] for p in cfg.get("paths", [])]
        if "topicPath" in cfg:
            paths.append(cfg["topicPath"])
        paths += list(cfg.get("topics", {}))
    return paths


def check_layout_against(msgs: dict) -> None:
    """Each path's topic was recorded and its fields exist on the recorded message."""
    for path in layout_paths():
        topic, _, fields = path.partition(".")
        if topic in ("/gnc/ctl/candidates", "/mob/planner/path", "/sim/fault"):
            continue      # MPC only / published with a plan / on a fault: not in a hold run
        assert topic in msgs, f"layout shows {topic}, which the run does not publish"
        value = msgs[topic][-1]
        for f in filter(None, fields.split(".")):
            value = getattr(value, f)
