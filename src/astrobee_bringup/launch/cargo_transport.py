"""The cargo-transport graph: router, simulator, planner, controller and the bag recorder.

Launch arguments (`name:=value`): scenario (config/scenarios/<name>.yaml, default
node2_to_jem), controller (a law of astrobee_control.registry: pd | mpc | ...), record
(true | false), bag_dir (default <run>/bag), clock (realtime | fast | lockstep; default
lockstep headless: the sim waits for each command, as fast as the graph answers; realtime
with gui), lockstep_timeout (wall s the sim
waits for a tick's command before stepping on; the sim's default when unset), gui (true |
false), bag_model / bag_variant / bag_resolution / bag_mass / fem_solver / flight_mode /
robots / realism (a preset of config/realism.yaml) (override the scenario: validated here
with the scenario before any process starts, then built by sim_node, which publishes the
result on /sim/scenario for the others), mission (true | false: run the mission client,
default true), safety (the CBF safety filter between the controller and the sim: true = in
the controller's process (its `safety` parameter: no extra process, no extra hop in the
lockstep loop), node = a safety_filter_node of its own between a controller's
gnc/ctl/command_nominal and the sim (for a controller that is not ours), false = none; default
true). One controller (and with safety:=node one
safety filter) per robot of the scenario, in the robot's namespace (`bumble/pd_controller_node`
publishes /bumble/gnc/ctl/command); with a bag held by several robots each controller takes
its share of the bag's mass. video (true | false:
render one MP4 per leg into the run folder, default: with demo), demo (true: fly DEMO_LEGS
in the same graph, the sim reset between the legs: node2_to_jem, node2_to_jem_fem_bag_bump (the
FEM bag, fast solver, strap grasp, a 5 N bump on the bag drawn from the seed) with PD, then
node2_to_jem_fem_bag_gov_uwm: the same carry, seed and bump flown by gov_uwm, the governed pair
law with the folded bag's lever, the clearance weight, the pair's rate damped along the route,
the corridor fit, the capped hold and the long way round when clearly sooner; video_compare.mp4
shows the two carries side by side).

Controller parameters: each law's node gets the law's defaults, then config/controllers.yaml's
section for it (`<law>: {name: value}`), then the scenario's own `controller_params:
{name: value}` for the law it names (when no controller:= is given; two legs flying one law
must agree on them), then the section of the file controller_params:=PATH names (the same
shape; for every robot flying that law), e.g. gov_clear, the governed pair law with its lever
and clearance weight (studies/lever_clearance.yaml):

    # gov_clear.yaml:  pair_gov: {lever: true, clearance: 0.3}
    astrobee launch cargo_transport scenario:=node2_to_jem_fem_bag_pair_gov \
        controller_params:=gov_clear.yaml

The merged overrides are checked before any process starts (a missing or unreadable file,
content that is not such a mapping, a law not registered, a parameter the law does not have,
a value of the wrong type or one the law's check refuses: one line, exit 1) and written to
<run>/params/<law>_controller_node.yaml; a law of the file no robot flies is checked, then
ignored.

Controllers: each robot gets the controller its scenario names (`controller:` in the scenario
file, pd when it names none; an explicit controller:= argument applies to every robot). A
per-robot controller, rather than a second graph run or a switch inside one controller node,
keeps the demo one graph, one recording, one summary.json: the pair_gov leg's robot (queen) has
its own pair_gov_controller_node in /queen, while the PD node of the default robot waits on topics no
sim publishes during that leg, as every Astrobee runs its own controller.
The mission client's exit ends the launch; post_run re-plots the flight from the closed bag.
With the mission running, the controller's death does not end the launch by itself: the sim's
watchdog stops the robot and raises a fault, the mission ends the leg on it (failed) and
exits, so the bag holds the fault and the coasting robot. Without it, the controller is required.
"""
from __future__ import annotations

import difflib
import math
import os
import re
import tempfile
from pathlib import Path
from typing import Any

from astrobee.config import ConfigError, load_yaml
from astrobee.overrides import (BAG_MODELS, FEM_SOLVERS, NO_BAG, OVERRIDE_KEYS, Overrides,
                                parse_overrides)
from astrobee.scenario import Scenario, ScenarioError
from astrobee_bringup.launcher import LaunchContext, flatten_params, write_params_file
from astrobee_bringup.process_group import LaunchError, NodeSpec
from astrobee_control import registry
from roszen.parameters import coerce, infer_type


# no bag (PD); the FEM bag on the strap grasp with a 5 N bump on the bag drawn from the seed,
# flown by PD and then, the same seed and bump, by the governed pair law as gov_uwm (pair_gov with
# the scenario's controller_params: lever, lever_from bag, clearance 0.3, momentum 1, fit 0.3,
# hold_error 0.2, unwind, unwind_margin 0.8; studies/unwind_margin_replication.yaml)
DEMO_LEGS = ("node2_to_jem", "node2_to_jem_fem_bag_bump", "node2_to_jem_fem_bag_gov_uwm")
# the same carry by two controllers, side by side in video_compare.mp4 (render_demo_compare)
DEMO_COMPARE = ("node2_to_jem_fem_bag_bump", "node2_to_jem_fem_bag_gov_uwm")
# on by default: transparent on Node 2 -> JEM (0 interventions, the same poses) and, in the
# controller's process, within the noise of off in lockstep (bench/safety_bench.py --graph)
SAFETY_DEFAULT = "true"
SAFETY_MODES = {"true": "controller", "yes": "controller", "1": "controller", "on": "controller",
                "controller": "controller", "node": "node",
                "false": "", "no": "", "0": "", "off": ""}

# the launch arguments, for `astrobee launch cargo_transport --show-args`: name -> (default, what)
ARGUMENTS = {
    "scenario": ("node2_to_jem", "config/scenarios/<name>.yaml to fly"),
    "controller": ("", f"{registry.choices_text(' | ')} for every robot ('': each scenario's "
                       "`controller:`, else pd)"),
    "controller_params": ("", "a YAML file `<law>: {name: value}` (config/controllers.yaml's "
                          "shape) whose values override config/controllers.yaml's for every "
                          "robot flying that law; checked before any process starts"),
    "clock": ("lockstep", "realtime | fast | lockstep (lockstep: the sim waits for each "
                          "command; realtime with gui)"),
    "lockstep_timeout": ("", "wall s the sim waits for a tick's command (the sim's default)"),
    "gui": ("false", "true: open the pybullet window (needs a display)"),
    "record": ("true", "record every topic into bag_dir"),
    "bag_dir": ("<run>/bag", "where the recording goes"),
    "mission": ("true", "run the mission client (its exit ends the launch)"),
    "safety": (SAFETY_DEFAULT, "the CBF safety filter between controller and sim: true (inside "
               "the controller's process) | node (a safety_filter_node of its own, for a "
               "controller that is not ours) | false"),
    "video": ("false (true with demo)", "render one MP4 per leg into the run folder"),
    "demo": ("false", "fly DEMO_LEGS (no bag; the FEM bag with a 5 N bump by PD, then by "
                      "gov_uwm (pair_gov): the same seed, the same bump), the sim reset between"),
    "bag_model": ("", f"scenario override: {' | '.join(BAG_MODELS + (NO_BAG,))}"),
    "bag_variant": ("", "scenario override: the cargo bag's variant"),
    "bag_resolution": ("", "scenario override: cargo bag mesh node count"),
    "bag_mass": ("", "scenario override: cargo bag mass in kg"),
    "fem_solver": ("", f"scenario override: the FEM bag's solver ({' | '.join(FEM_SOLVERS)})"),
    "grasp": ("", "scenario override: how the gripper holds the bag's handle: strap | hinge | "
              "clamp (astrobee_sim.grasp)"),
    "flight_mode": ("", "scenario override: a flight mode (e.g. nominal, quiet)"),
    "robots": ("", "scenario override: comma-separated robot names (namespaces)"),
    "realism": ("", "realism preset of config/realism.yaml (off, astrobee, harsh; '' = the "
                "scenario's): EKF noise, actuation noise + lag, bumps, told bag mass"),
    "seed": ("0", "the simulator's seed (realism noise, bumps; as a study row's seed)"),
}


# the words a flag argument takes (LaunchContext.flag reads the true ones; anything else is refused)
FLAG_WORDS = ("true", "false", "yes", "no", "1", "0", "on", "off")
FLAGS = ("record", "gui", "mission", "demo", "video")
SEED_MAX = 2**63 - 1                # sim_node's seed is a ROS integer parameter (int64)
LOCKSTEP_TIMEOUT_MAX = 3600.0       # sim_node's lockstep_timeout range (astrobee_sim.sim_params)


def _yaml_float(value: float) -> str:
    """`value` as text a ROS parameter (YAML) reads as a float: 1e-05 -> 1.0e-05 (YAML 1.1
    takes an exponent only after a dot and with a sign)."""
    mantissa, e, exponent = repr(float(value)).partition("e")
    if "." not in mantissa:
        mantissa += ".0"
    return mantissa + (f"e{'' if exponent[0] in '+-' else '+'}{exponent}" if e else "")


def check_arguments(ctx: LaunchContext) -> None:
    """The plain launch arguments (flags, seed, lockstep_timeout, bag_dir) checked before any
    process starts or any run folder is made: one LaunchError line naming the argument."""
    given = ctx.arguments
    for key in FLAGS:
        if key in given and given[key].lower() not in FLAG_WORDS:
            raise LaunchError(f"{key} must be true or false (yes/no, on/off, 1/0), "
                              f"got '{given[key]}'")
    if "seed" in given and not (re.fullmatch(r"[0-9]+", given["seed"])
                                and int(given["seed"]) <= SEED_MAX):
        raise LaunchError(f"seed must be an integer 0..2**63-1, got '{given['seed']}'")
    if given.get("lockstep_timeout", "").strip():
        try:
            timeout = float(given["lockstep_timeout"])
        except ValueError:
            timeout = math.nan
        if not (math.isfinite(timeout) and 0 < timeout <= LOCKSTEP_TIMEOUT_MAX):
            raise LaunchError(f"lockstep_timeout must be > 0 and <= {LOCKSTEP_TIMEOUT_MAX:g} s, "
                              f"got '{given['lockstep_timeout']}'")
    if "bag_dir" in given and ctx.flag("record", True):
        _check_bag_dir(ctx, given["bag_dir"])


def _check_bag_dir(ctx: LaunchContext, bag_dir: str) -> None:
    """The recorder makes bag_dir itself: it must not exist yet and its parent must be a
    folder we can make a folder in (the run folder, made later, counts)."""
    if not bag_dir.strip():
        raise LaunchError("bag_dir must be a folder path, got ''")
    path = Path(bag_dir)
    if path.exists() or path.is_symlink():
        raise LaunchError(f"bag_dir {bag_dir} already exists (the recorder makes a new folder)")
    parent = path.absolute().parent
    if parent == ctx.run_dir.absolute() and not parent.exists():
        return
    if not parent.is_dir():
        raise LaunchError(f"bag_dir {bag_dir}: {parent} is not a folder")
    try:                                # the one way to know: make a folder there and remove it
        os.rmdir(tempfile.mkdtemp(prefix=".bag_dir-check-", dir=parent))
    except OSError as exc:
        raise LaunchError(f"bag_dir {bag_dir}: cannot make a folder in {parent} "
                          f"({exc.strerror or exc})") from None


def read_controller_params(arg: str) -> dict[str, dict[str, Any]]:
    """The controller_params file: law -> {name: value} (one LaunchError line naming the
    argument for a file that is missing, unreadable, not YAML or not such a mapping)."""
    where = f"controller_params {arg}"
    if not arg.strip():
        raise LaunchError("controller_params must be a YAML file path, got ''")
    path = Path(arg).absolute()     # absolute: load_yaml looks a missing relative one up in config/
    if not path.is_file():
        raise LaunchError(f"{where}: {'not a file' if path.exists() else 'no such file'}")
    try:
        data = load_yaml(path)
    except OSError as exc:
        raise LaunchError(f"{where}: cannot read it ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise LaunchError(f"{where}: not a text (UTF-8) file") from None
    except ConfigError as exc:          # load_yaml: a YAML error as its cause, else not a mapping
        mark = getattr(exc.__cause__, "problem_mark", None)
        if exc.__cause__ is None:
            raise LaunchError(f"{where}: does not hold a mapping <law>: {{name: value}}") from None
        raise LaunchError(f"{where}: not valid YAML"
                          + (f": {exc.__cause__.problem} (line {mark.line + 1}, column "
                             f"{mark.column + 1})" if mark is not None else "")) from None
    known = registry.names()
    for kind, section in data.items():
        if kind not in known:
            raise LaunchError(f"{where}: {kind!r} is not a controller ({registry.choices_text()})")
        if section is not None and not isinstance(section, dict):
            raise LaunchError(f"{where}: {kind} must map parameter names to values, "
                              f"got {section!r}")
    return {kind: dict(section or {}) for kind, section in data.items()}


def controller_overrides(ctx: LaunchContext, kinds: set[str],
                         scenario_params: dict[str, tuple[str, dict]] | None = None
                         ) -> dict[str, dict[str, Any]]:
    """Each law of `kinds` and of the controller_params file: config/controllers.yaml's section,
    a scenario's `controller_params` over it (scenario_params: law -> (scenario, params)), the
    file's over both, checked (names, parameter types, the law's own check): law ->
    {name: value}. A bad one is one LaunchError line naming where it came from."""
    site_path = ctx.config_dir / "controllers.yaml"
    site = load_yaml(site_path)
    arg = ctx.arg("controller_params")
    given = read_controller_params(arg) if "controller_params" in ctx.arguments else {}
    scenario_params = scenario_params or {}
    out = {}
    for kind in sorted(kinds | set(given)):
        law = registry.get(kind)
        section = site.get(kind) or {}
        if not isinstance(section, dict):
            raise LaunchError(f"controller {kind}: {site_path}: {kind} must map parameter names "
                              f"to values, got {section!r}")
        leg, scen = scenario_params.get(kind, ("", {}))
        section = {**section, **scen}
        leg_names = flatten_params(scen)     # the names the scenario set (errors name it)
        mine = flatten_params(given.get(kind, {}))
        for name, value in {**flatten_params(section), **mine}.items():
            where = (f"controller_params {arg}" if name in mine
                     else f"scenario {leg}: controller_params" if name in leg_names
                     else f"controller {kind}: {site_path}")
            if name not in law.parameters:
                near = difflib.get_close_matches(name, list(law.parameters), n=1)
                raise LaunchError(f"{where}: {kind} has no parameter {name!r}"
                                  + (f" (did you mean {near[0]!r}?)" if near else ""))
            try:                        # the type check the node's declare_parameter makes
                coerce(value, infer_type(law.parameters[name]))
            except (TypeError, ValueError) as exc:
                raise LaunchError(f"{where}: {kind} parameter {name!r}: {exc}") from None
        merged = {**section, **given.get(kind, {})}
        try:                            # the law's defaults + the merged overrides, checked
            law.check_params(merged)
        except ValueError as exc:
            where = (f"controller_params {arg}: {kind}" if mine
                     else f"scenario {leg}: controller_params" if leg_names
                     else f"controller {kind}")
            raise LaunchError(f"{where}: {exc}") from None
        out[kind] = merged
    return out


def scenario_overrides(ctx: LaunchContext) -> Overrides:
    """Launch arguments that change the scenario (astrobee.overrides: one parser, one line)."""
    try:
        return parse_overrides({k: ctx.arg(k) for k in OVERRIDE_KEYS}, source="launch")
    except ScenarioError as exc:
        raise LaunchError(str(exc)) from None


def generate_nodes(ctx: LaunchContext) -> list[NodeSpec]:
    check_arguments(ctx)
    scenario = ctx.arg("scenario", "node2_to_jem")
    controller = ctx.arg("controller", "")      # '' : each scenario's own (pd if it names none)
    known = registry.names()
    if controller and controller not in known:
        raise LaunchError(f"controller must be {registry.choices_text()}, got '{controller}'")
    demo = ctx.flag("demo")
    legs = list(DEMO_LEGS) if demo else [scenario]
    if demo:
        scenario = legs[0]
    gui = ctx.flag("gui")
    if gui and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise LaunchError("gui:=true needs a display (DISPLAY is not set); run headless and "
                          "watch the run with `astrobee bag render` instead")
    clock = ctx.arg("clock", "realtime" if gui else "lockstep")
    if clock not in ("realtime", "fast", "lockstep"):
        raise LaunchError(f"clock must be realtime, fast or lockstep, got '{clock}'")
    overrides = scenario_overrides(ctx)
    # every leg is built here once, with the overrides, before any process starts; each robot
    # of any leg gets its own controller (and safety filter) in its namespace
    robots: list[str] = []
    shares: dict[str, float] = {}       # robot -> its share of a bag carried by several robots
    kinds: dict[str, str] = {}          # robot -> its controller (a registered law)
    by_scenario: dict[str, tuple[str, dict]] = {}   # law -> (leg, its scenario's parameters)
    for leg in legs:
        try:
            built = Scenario.load(leg, overrides)
        except ScenarioError as exc:
            raise LaunchError(f"scenario {leg}: {exc}") from None
        names = list(built.robot_names)
        robots += [r for r in names if r not in robots]
        kind = controller or str(built.extra.get("controller") or "pd")
        if kind not in known:
            raise LaunchError(f"scenario {leg}: controller must be {registry.choices_text()}, "
                              f"got '{kind}'")
        for r in names:
            if kinds.setdefault(r, kind) != kind:
                raise LaunchError(f"robot {r or '(default)'} flies with {kinds[r]} in one leg and "
                                  f"{kind} in {leg}: one controller per robot")
        if not controller:              # the scenario's own law flies with its parameters
            params = built.extra.get("controller_params") or {}
            if not isinstance(params, dict):
                raise LaunchError(f"scenario {leg}: controller_params must map parameter names "
                                  f"to values, got {params!r}")
            first = by_scenario.setdefault(kind, (leg, params))
            if first[1] != params:
                raise LaunchError(f"scenario {leg}: {kind} flies with other controller_params "
                                  f"than in {first[0]}: one set of parameters per law")
        if built.bag is not None and len(names) > 1 and built.bag.handles == len(names):
            shares.update({r: built.bag.mass / len(names) for r in names})
    # config/controllers.yaml's sections with controller_params' over them, checked; a law of
    # the file no robot flies is checked and left out
    overrides_by_law = controller_overrides(ctx, set(kinds.values()), by_scenario)
    ctl_params = {}                     # controller kind -> its parameters file
    for kind in sorted(set(kinds.values())):
        law = registry.get(kind)
        # the node declares the law's defaults; the file carries the merged overrides
        ctl_params[kind] = write_params_file(
            ctx.run_dir / "params" / f"{law.node_name}.yaml", law.node_name,
            flatten_params(overrides_by_law[kind]))
    common = {"scenario": scenario, "use_sim_time": True}
    sim_params = {**common, "clock_mode": clock, "gui": gui}
    if ctx.arg("lockstep_timeout").strip():     # checked by check_arguments
        sim_params["lockstep_timeout"] = _yaml_float(float(ctx.arg("lockstep_timeout")))
    if ctx.arg("seed"):
        sim_params["seed"] = int(ctx.arg("seed"))
    sim_params.update(overrides.as_parameters())   # the sim builds the scenario with them
    mission = ctx.flag("mission", True)
    safety = SAFETY_MODES.get(ctx.arg("safety", SAFETY_DEFAULT).strip().lower())
    if safety is None:
        raise LaunchError(f"safety must be true, node or false, got '{ctx.arg('safety')}'")
    # deterministic lockstep: the sim paused until the mission has the graph ready and hands
    # the segment over at a fixed sim time (mission --handover): the same seed, the same bag
    handover = mission and clock == "lockstep"
    if handover:
        sim_params["start_paused"] = True
    port = ctx.port
    nodes = [
        NodeSpec("router", kind="router", command=["router", "--port", str(port)],
                 ros2_command=["ros2", "run", "rmw_zenoh_cpp", "rmw_zenohd"]),
        NodeSpec("sim_node", "astrobee_sim", "sim_node",
                 parameters=[sim_params]),
        NodeSpec("planner_node", "astrobee_planning", "planner_node", parameters=[common]),
    ]
    for robot in robots:     # "" keeps the root namespace; "bumble" -> /bumble/gnc/ctl/command ...
        per_robot = {"use_sim_time": True}
        if robot in shares:  # a bag held by several robots: each feeds forward its share
            per_robot["bag_mass"] = shares[robot]
        law = registry.get(kinds[robot])
        if "seed" in law.parameters and "seed" in sim_params:  # its sampling: the run's seed
            per_robot["seed"] = sim_params["seed"]
        if safety == "controller":      # the CBF filter inside the controller's process
            per_robot["safety"] = True
        ctl_name = law.node_name        # a law without an executable of its own: controller_node <law>
        own = bool(law.executable)
        nodes.append(NodeSpec(f"{robot}/{ctl_name}" if robot else ctl_name, "astrobee_control",
                              law.executable or registry.GENERIC_EXECUTABLE,
                              parameters=[ctl_params[kinds[robot]], per_robot],
                              arguments=[] if own else [law.name],
                              namespace=robot,
                              required=not mission,
                              ros_args=([] if own else ["-r", f"__node:={ctl_name}"])
                              + (["-r", "gnc/ctl/command:=gnc/ctl/command_nominal"]
                                 if safety == "node" else [])))
        if safety == "node":    # the CBF filter in a process of its own between controller and sim
            nodes.append(NodeSpec(f"{robot}/safety_filter_node" if robot else "safety_filter_node",
                                  "astrobee_control", "safety_filter_node", namespace=robot,
                                  parameters=[{"use_sim_time": True}], required=not mission))
    if ctx.flag("record", True):
        bag_dir = ctx.arg("bag_dir", str(ctx.run_dir / "bag"))
        # stamped on sim time like every node of the launch: a lockstep flight replays at its pace
        nodes.append(NodeSpec("recorder", kind="recorder",
                              command=["bag", "record", "-a", "--use-sim-time", "-o", bag_dir],
                              ros2_command=["ros2", "bag", "record", "-a", "--use-sim-time",
                                            "-s", "mcap", "-o", bag_dir]))
    if mission:
        import sys
        args = [a for leg in legs for a in ("--scenario", leg)] + ["--run-dir", str(ctx.run_dir)]
        if handover:
            args += ["--handover"] + (["--await-recorder"] if ctx.flag("record", True) else [])
        if demo:                        # the PD leg is there to fail where gov_uwm does not
            args += ["--keep-going"]
        nodes.append(NodeSpec("mission", "astrobee_bringup", "mission", kind="client",
                              command=["run", "astrobee_bringup", "mission", *args],
                              ros2_command=[sys.executable, "-m", "astrobee_bringup.mission", *args]))
    return nodes


def post_run(ctx: LaunchContext, status: int) -> None:
    """Once the graph has stopped: plots and bag figures of the run read back from its bag."""
    from astrobee_bringup.summary import finalize
    bag_dir = ctx.arg("bag_dir", str(ctx.run_dir / "bag"))
    if ctx.flag("record", True) and ctx.flag("mission", True):
        print(finalize(ctx.run_dir, bag_dir), flush=True)
        if ctx.flag("video", ctx.flag("demo")):      # one video per leg (default with the demo)
            from astrobee_bringup.render_recording import render_demo_legs
            for path in render_demo_legs(ctx.run_dir, bag_dir):
                print(f"[video] {path}", flush=True)
            if ctx.flag("demo"):                    # at 8x: half the frames of a leg's
                from astrobee_bringup.render_recording import render_demo_compare
                out = render_demo_compare(ctx.run_dir, DEMO_COMPARE, bag_dir, speed=8.0)
                if out is not None:
                    print(f"[video] {out} ({' vs '.join(DEMO_COMPARE)})", flush=True)
            _print_video_errors(ctx.run_dir / "summary.json")


def _print_video_errors(summary: Path) -> None:
    """One line per leg left without a video, with the reason summary.json notes."""
    import json
    try:
        legs = json.loads(summary.read_text()).get("legs", [])
    except (OSError, ValueError):
        return
    for leg in legs:
        if leg.get("video_error"):
            print(f"[video] {leg.get('scenario', '?')}: not rendered: {leg['video_error']}",
                  flush=True)
