"""The cargo-transport graph: router, simulator, planner, controller and the bag recorder.

Launch arguments (`name:=value`): scenario (config/scenarios/<name>.yaml, default
node2_to_jem), controller (pd | mpc), record (true | false), bag_dir (default <run>/bag),
clock (realtime | fast | lockstep; default lockstep headless: the sim waits for each
command, as fast as the graph answers; realtime with gui), lockstep_timeout (wall s the sim
waits for a tick's command before stepping on; the sim's default when unset), gui (true |
false), bag_model / bag_variant / bag_resolution (override the scenario's bag on sim_node),
mission (true | false: run the mission client, default true), demo (true: fly
node2_to_jem then node2_to_jem_bag in the same graph, the sim reset between the legs).
The mission client's exit ends the launch; post_run re-plots the flight from the closed bag.
With the mission running, the controller's death does not end the launch by itself: the sim's
watchdog stops the robot and raises a fault, the mission ends the leg on it (failed) and
exits, so the bag holds the fault and the coasting robot. Without it, the controller is required.
"""
from __future__ import annotations

from astrobee.config import load_yaml
from astrobee_bringup.launcher import LaunchContext, NodeSpec, LaunchError, flatten_params, write_params_file


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
    demo = ctx.flag("demo")
    legs = ["node2_to_jem", "node2_to_jem_bag"] if demo else [scenario]
    if demo:
        scenario = legs[0]
    gui = ctx.flag("gui")
    clock = ctx.arg("clock", "realtime" if gui else "lockstep")
    if clock not in ("realtime", "fast", "lockstep"):
        raise LaunchError(f"clock must be realtime, fast or lockstep, got '{clock}'")
    common = {"scenario": scenario, "use_sim_time": True}
    sim_params = {**common, "clock_mode": clock, "gui": gui}
    if ctx.arg("lockstep_timeout"):
        try:
            sim_params["lockstep_timeout"] = float(ctx.arg("lockstep_timeout"))
        except ValueError:
            raise LaunchError(f"lockstep_timeout must be a number of seconds, "
                              f"got '{ctx.arg('lockstep_timeout')}'") from None
        if not sim_params["lockstep_timeout"] > 0:
            raise LaunchError("lockstep_timeout must be > 0")
    for key in ("bag_model", "bag_variant"):       # override the scenario's bag
        if ctx.arg(key):
            sim_params[key] = ctx.arg(key)
    if ctx.arg("bag_resolution"):
        try:
            sim_params["bag_resolution"] = int(ctx.arg("bag_resolution"))
        except ValueError:
            raise LaunchError(f"bag_resolution must be a node count, "
                              f"got '{ctx.arg('bag_resolution')}'") from None
    mission = ctx.flag("mission", True)
    port = ctx.port
    nodes = [
        NodeSpec("router", kind="router", command=["router", "--port", str(port)],
                 ros2_command=["ros2", "run", "rmw_zenoh_cpp", "rmw_zenohd"]),
        NodeSpec("sim_node", "astrobee_sim", "sim_node",
                 parameters=[sim_params]),
        NodeSpec("planner_node", "astrobee_planning", "planner_node", parameters=[common]),
        NodeSpec(ctl_name, "astrobee_control", ctl_name,
                 parameters=[ctl_params, {"use_sim_time": True}], required=not mission),
    ]
    if ctx.flag("record", True):
        bag_dir = ctx.arg("bag_dir", str(ctx.run_dir / "bag"))
        nodes.append(NodeSpec("recorder", kind="recorder",
                              command=["bag", "record", "-a", "-o", bag_dir],
                              ros2_command=["ros2", "bag", "record", "-a", "-s", "mcap",
                                            "-o", bag_dir]))
    if mission:
        import sys
        args = [a for leg in legs for a in ("--scenario", leg)] + ["--run-dir", str(ctx.run_dir)]
        nodes.append(NodeSpec("mission", "astrobee", "mission", kind="client",
                              command=["run", "astrobee", "mission", *args],
                              ros2_command=[sys.executable, "-m", "astrobee_bringup.mission", *args]))
    return nodes


def post_run(ctx: LaunchContext, status: int) -> None:
    """Once the graph has stopped: plots and bag figures of the run read back from its bag."""
    from astrobee_bringup.summary import finalize
    bag_dir = ctx.arg("bag_dir", str(ctx.run_dir / "bag"))
    if ctx.flag("record", True) and ctx.flag("mission", True):
        print(finalize(ctx.run_dir, bag_dir), flush=True)
