"""RIHS01 type hashes: known values, zenoh-ros2-sdk's independent computation, rosbags' one."""
import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from zenoh_ros2_sdk import utils as zutils

from roszen import typestore as ts

KNOWN = {
    "std_msgs/msg/String": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    "example_interfaces/srv/AddTwoInts":
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a",
}

COMMON_MSGS = [
    "std_msgs/msg/String", "std_msgs/msg/Header", "geometry_msgs/msg/Pose",
    "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped",
    "geometry_msgs/msg/Wrench", "geometry_msgs/msg/Vector3", "geometry_msgs/msg/Point",
    "geometry_msgs/msg/Quaternion", "geometry_msgs/msg/TransformStamped", "sensor_msgs/msg/Imu",
    "nav_msgs/msg/Path", "nav_msgs/msg/Odometry", "visualization_msgs/msg/MarkerArray",
    "tf2_msgs/msg/TFMessage", "rosgraph_msgs/msg/Clock", "builtin_interfaces/msg/Time",
    "rcl_interfaces/msg/Log", "rcl_interfaces/msg/ParameterEvent",
]
COMMON_SRVS = [
    "std_srvs/srv/Trigger", "std_srvs/srv/SetBool", "std_srvs/srv/Empty",
    "example_interfaces/srv/AddTwoInts", "rcl_interfaces/srv/GetParameters",
    "rcl_interfaces/srv/SetParameters", "rcl_interfaces/srv/ListParameters",
    "rcl_interfaces/srv/DescribeParameters", "rcl_interfaces/srv/GetParameterTypes",
    "rcl_interfaces/srv/SetParametersAtomically",
]
ASTROBEE = [n for n in ts.list_types() if n.startswith("astrobee_msgs/")]


def _deps(specs) -> dict[str, str]:
    """{type: .msg text} of every message type reachable from `specs` (for zenoh-ros2-sdk)."""
    out: dict[str, str] = {}
    stack = [d for s in specs for d in s.dependencies()]
    while stack:
        n = stack.pop()
        if n not in out:
            spec = ts.get_spec(n)
            out[n] = spec.definition()
            stack.extend(spec.dependencies())
    return out


@pytest.mark.parametrize("name", sorted(KNOWN))
def test_known_hashes(name):
    assert ts.type_hash(name) == KNOWN[name]


def test_hash_accepts_every_name_form():
    h = KNOWN["std_msgs/msg/String"]
    assert ts.type_hash("std_msgs/String") == h
    assert ts.type_hash("std_msgs::msg::dds_::String_") == h


@pytest.mark.parametrize("name", COMMON_MSGS + [n for n in ASTROBEE if "/msg/" in n])
def test_message_hash_matches_zenoh_ros2_sdk(name):
    spec = ts.get_spec(name)
    theirs = zutils.compute_type_hash_from_msg(name, spec.definition(), _deps([spec]))
    assert ts.type_hash(name) == theirs


SDK_NO_BOUNDED_NESTED = pytest.mark.xfail(
    strict=True, reason="zenoh-ros2-sdk's parser does not understand nested bounded sequences "
    "(ParameterDescriptor's FloatingPointRange[<=1]); checked against rosbags below instead")


@pytest.mark.parametrize("name", [
    pytest.param(n, marks=SDK_NO_BOUNDED_NESTED) if n.endswith("DescribeParameters") else n
    for n in COMMON_SRVS + [n for n in ASTROBEE if "/srv/" in n]])
def test_service_hash_matches_zenoh_ros2_sdk(name):
    srv = ts.get_service_spec(name)
    req, resp = srv.request.definition(), srv.response.definition()
    # zenoh-ros2-sdk refuses an empty part; rosidl hashes it as this dummy member anyway
    dummy = "uint8 structure_needs_at_least_one_member\n"
    req, resp = (req if req.strip() else dummy), (resp if resp.strip() else dummy)
    theirs = zutils.compute_service_type_hash(name, req, resp, _deps([srv.request, srv.response]))
    assert ts.type_hash(name) == theirs


def test_empty_service_hash_built_like_rosidl():
    """std_srvs/Empty: both parts get the dummy uint8 member; the Event wraps them."""
    desc = ts._rihs.type_description(
        ts._rihs.service_root(ts.get_service_spec("std_srvs/srv/Empty")), ts.get_spec)
    refs = {d["type_name"]: d for d in desc["referenced_type_descriptions"]}
    assert list(refs) == sorted(refs)
    for part in ("std_srvs/srv/Empty_Request", "std_srvs/srv/Empty_Response"):
        assert refs[part]["fields"] == [{"name": "structure_needs_at_least_one_member", "type": {
            "type_id": 3, "capacity": 0, "string_capacity": 0, "nested_type_name": ""}}]
    event = refs["std_srvs/srv/Empty_Event"]["fields"]
    assert [f["type"]["type_id"] for f in event] == [1, 97, 97]
    gid = [f for f in refs["service_msgs/msg/ServiceEventInfo"]["fields"] if f["name"] == "client_gid"]
    assert gid[0]["type"]["type_id"] == 48 + 3  # char[16] hashed as uint8[16], as rosidl does


@pytest.mark.parametrize("name", [n for n in COMMON_MSGS])
def test_message_hash_matches_rosbags_store(name):
    assert ts.type_hash(name) == get_typestore(Stores.ROS2_JAZZY).hash_rihs01(name)


def test_astrobee_hashes_match_rosbags_parser():
    """rosbags' own .msg parser on our files gives the same hashes (no char in astrobee_msgs)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name in ASTROBEE:
        if "/msg/" in name:
            types.update(get_types_from_msg(ts.definition_text(name), name))
    store.register(types)
    for name in types:
        assert ts.type_hash(name) == store.hash_rihs01(name), name


@pytest.mark.parametrize("name", COMMON_SRVS + [n for n in ASTROBEE if "/srv/" in n])
def test_service_parts_match_rosbags_parser(name):
    """Request/Response hashes from rosbags' parser on the same .srv halves (none has char)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    srv = ts.get_service_spec(name)
    types = {}
    for msg in ASTROBEE:
        if "/msg/" in msg:
            types.update(get_types_from_msg(ts.definition_text(msg), msg))
    for part in (srv.request, srv.response):
        types.update(get_types_from_msg(part.definition(), part.name))
    store.register(_fix_srv_names(types))
    for part in (srv.request, srv.response):
        assert ts.type_hash(part.name) == store.hash_rihs01(part.name), part.name


def _fix_srv_names(types: dict) -> dict:
    """rosbags parses "pkg/srv/X_Request" as "pkg/srv/msg/X_Request": undo that (known gap)."""
    def fix(name: str) -> str:
        if "/srv/msg/" not in name:
            return name
        pkg, _, _, base = name.split("/")
        return f"{pkg}/srv/{base}" if base.endswith(("_Request", "_Response")) else f"{pkg}/msg/{base}"

    def fix_desc(desc):
        if isinstance(desc, str):
            return fix(desc)
        if isinstance(desc, tuple):
            return tuple(fix_desc(d) for d in desc)
        return desc

    return {fix(k): (c, [(n, fix_desc(d)) for n, d in f]) for k, (c, f) in types.items()}


def test_char_is_hashed_as_uint8():
    """std_msgs/Char: rosidl maps .msg char to uint8 (rosbags' CHAR id would give another hash)."""
    desc = ts._rihs.type_description(ts.get_spec("std_msgs/msg/Char"), ts.get_spec)
    assert desc["type_description"]["fields"][0]["type"]["type_id"] == 3
    assert ts.type_hash("std_msgs/msg/Char") != get_typestore(Stores.ROS2_JAZZY).hash_rihs01(
        "std_msgs/msg/Char")


def test_request_response_hashes_and_dds_names():
    assert ts.type_hash("example_interfaces/srv/AddTwoInts_Request").startswith("RIHS01_")
    assert ts.type_hash("example_interfaces/srv/AddTwoInts_Request") != ts.type_hash(
        "example_interfaces/srv/AddTwoInts_Response")
    assert ts.dds_type_name("std_msgs/msg/String") == "std_msgs::msg::dds_::String_"
    assert ts.dds_type_name("example_interfaces/srv/AddTwoInts") == \
        "example_interfaces::srv::dds_::AddTwoInts_"
    assert ts.normalize_type_name("std_srvs/Trigger") == "std_srvs/srv/Trigger"
    assert ts.normalize_type_name("std_msgs::msg::dds_::String_") == "std_msgs/msg/String"
