"""The `astrobee` command: the ros2-style verbs of roszen.cli plus astrobee's own (launch,
study, bag render), all entry points (roszen.cli.registry); `astrobee -h` lists them.

    astrobee run astrobee_sim sim_node --ros-args -p scenario:=node2_to_jem
    astrobee launch cargo_transport [name:=value ...] [--port 7447]
    astrobee topic list | echo /mob/state | ...   (see `astrobee -h`)
"""
from __future__ import annotations

import sys

from roszen.cli import main as roszen_main
from roszen.cli.common import CliError
from roszen.cli.registry import Verb

GROUPS = ("roszen.verbs", "astrobee.verbs")

# the verbs with their own parsers; pyproject.toml's entry points name these objects
LAUNCH = Verb("start a launch description (astrobee_bringup/launch/NAME.py): "
              "launch NAME [arg:=value ...]", "astrobee_bringup.cli:launch_main")
STUDY = Verb("Monte Carlo studies: study run FILE | report DIR | reflow DIR ROW",
             "astrobee_lab.study.cli:main")
RENDER = Verb("render a recorded run to MP4/GIF, headless: bag render RECORDING -o flight.mp4",
              "astrobee_bringup.render_recording:main")


def launch_main(argv: list[str]) -> int:
    """`astrobee launch`: a bad argument is one line; Ctrl-C before the launcher took over the
    signals exits 130."""
    try:
        return _launch(argv)
    except CliError as exc:
        print(f"astrobee launch: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


def _launch(argv: list[str]) -> int:
    from astrobee_bringup import launcher
    from astrobee_bringup.process_group import LaunchError

    from roszen.cli.common import Parser     # a bad option is one line, not a usage dump
    p = Parser(prog="astrobee launch", description="Start a launch description's nodes.")
    p.add_argument("name", nargs="?", help="launch description (module in astrobee_bringup/launch/ "
                   "or a .py file)")
    p.add_argument("args", nargs="*", help="launch arguments name:=value")
    p.add_argument("--port", type=int, default=7447, help="router port (default 7447)")
    p.add_argument("--run-dir", help="directory for params and the bag (default runs/<time>)")
    p.add_argument("--ros2", dest="ros2", action="store_true", default=None,
                   help="start nodes with `ros2 run` (default: when ros2 + rmw_zenoh found)")
    p.add_argument("--no-ros2", dest="ros2", action="store_false")
    p.add_argument("--demo", action="store_true", help="shorthand for demo:=true")
    p.add_argument("--gui", action="store_true", help="shorthand for gui:=true (pybullet window)")
    p.add_argument("--scenario", help="shorthand for scenario:=NAME")
    p.add_argument("--list", action="store_true", help="list launch descriptions")
    p.add_argument("-s", "--show-args", "--show-arguments", dest="show_args", action="store_true",
                   help="list the launch description's arguments with defaults, then exit")
    p.add_argument("--sigint-timeout", type=float, default=5.0,
                   help="seconds a child gets to exit after SIGINT before SIGTERM (default 5)")
    p.add_argument("--sigterm-timeout", type=float, default=3.0,
                   help="seconds after SIGTERM before SIGKILL (default 3)")
    p.add_argument("--stop-grace", type=float, default=0.75,
                   help="seconds between the nodes' exit and stopping the recorder, so it "
                        "records their last messages (default 0.75)")
    # launch arguments anywhere on the line, before or after options (as `ros2 launch`)
    a = p.parse_intermixed_args(argv)
    if a.stop_grace < 0:
        raise CliError(f"--stop-grace must be >= 0, got {a.stop_grace:g}")
    if a.list or not a.name:
        print("\n".join(launcher.list_descriptions()))
        return 0 if a.list else 2
    if a.show_args:
        try:
            print(launcher.format_arguments(a.name), end="")
        except LaunchError as exc:
            raise CliError(str(exc)) from None
        return 0
    arguments = {}
    for item in a.args:
        key, sep, value = item.partition(":=")
        if not sep or not key:
            raise CliError(f"launch argument must be name:=value, got '{item}'")
        arguments[key] = value
    if a.demo:
        arguments.setdefault("demo", "true")
    if a.gui:
        arguments.setdefault("gui", "true")
    if a.scenario:
        arguments.setdefault("scenario", a.scenario)
    from pathlib import Path
    try:
        return launcher.launch(a.name, arguments, port=a.port, use_ros2=a.ros2,
                               run_dir=Path(a.run_dir) if a.run_dir else None, 
                               sigint_timeout=a.sigint_timeout,
                               sigterm_timeout=a.sigterm_timeout, stop_grace=a.stop_grace)
    except LaunchError as exc:
        raise CliError(str(exc)) from None


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `astrobee` console command."""
    return roszen_main(argv, prog="astrobee", groups=GROUPS,
                       description="Astrobee cargo transport: a ROS 2 (Jazzy) style node graph")


if __name__ == "__main__":
    sys.exit(main())
