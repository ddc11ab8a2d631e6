"""The cargo-transport graph: router, simulator, planner, controller and the bag recorder.

Launch arguments (`name:=value`): scenario (config/scenarios/<name>.yaml, default
node2_to_jem), controller (pd | mpc), record (true | false), bag_dir (default <run>/bag).
"""
from __future__ import annotations

from astrobee.config import load_yaml
from astrobee.launcher import LaunchContext, NodeSpec, LaunchError, flatten_params, write_params_file


def generate_nodes(ctx: LaunchContext) -> list[NodeSpec]:
    scenario = ctx.arg("scenario", "node2_to_jem")
    if not (ctx.config_dir / "scenarios" / f"{scenario}.yaml").is_file():
        raise LaunchError(f"unknown scenario '{scenario}' (no config/scenarios/{scenario}.yaml)")
    controller = ctx.arg("controller", "pd")
    if controller not in ("pd", "mpc"):
        raise LaunchError(f"controller must be pd or mpc, got '{controller}'")
    ctl_cfg = load_yaml(ctx.config_dir / "controllers.yaml").get(controller, {})
    ctl_name = f"{controller}_controller_node"
    ctl_params = write_params_file(ctx.run_dir / "params" / f"{ctl_name}.yaml", ctl_name,
                                   {**flatten_params(ctl_cfg), "scenario": scenario})
    common = {"scenario": scenario, "use_sim_time": True}
    port = ctx.port
    nodes = [
        NodeSpec("router", kind="router", command=["router", "--port", str(port)],
                 ros2_command=["ros2", "run", "rmw_zenoh_cpp", "rmw_zenohd"]),
        NodeSpec("sim_node", "astrobee_sim", "sim_node", parameters=[common]),
        NodeSpec("planner_node", "astrobee_planning", "planner_node", parameters=[common]),
        NodeSpec(ctl_name, "astrobee_control", ctl_name,
                 parameters=[ctl_params, {"use_sim_time": True}]),
    ]
    if ctx.flag("record", True):
        bag_dir = ctx.arg("bag_dir", str(ctx.run_dir / "bag"))
        nodes.append(NodeSpec("recorder", kind="recorder",
                              command=["bag", "record", "-a", "-o", bag_dir],
                              ros2_command=["ros2", "bag", "record", "-a", "-s", "mcap",
                                            "-o", bag_dir]))
    return nodes
