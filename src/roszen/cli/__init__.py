"""ros2-style command verbs over roszen: topic, service, node, param, interface, bag, run, router.

`main(argv, prog, groups)` is what `astrobee <verb> ...` (and `python -m roszen.cli`) runs. The
verbs are entry points (roszen.cli.registry): the parser and its usage text are built from
them. Syntax and output follow the `ros2` command so the same habits and scripts work.
"""
from __future__ import annotations

import argparse
import sys
from typing import Sequence

from roszen.cli import registry
from roszen.cli.common import CliError, Parser, line_buffered
from roszen.names import InvalidNameError
from roszen.yamltext import YamlError

GROUPS = ("roszen.verbs",)
# what a user typed wrong: one line `<prog> <verb>: <reason>`, exit 1, no traceback
USER_ERRORS = (CliError, InvalidNameError, YamlError)

# the verbs with their own parsers (pyproject.toml's entry points name these objects)
RUN = registry.Verb("start one node (like `ros2 run`): run PACKAGE EXECUTABLE [--ros-args ...]",
                    "roszen.cli.run:main")
ROUTER = registry.Verb("run the Zenoh router (rmw_zenohd equivalent): router [--port P]",
                       "roszen.cli.router:main")


def build_parser(prog: str, groups: Sequence[str] = GROUPS,
                 description: str = "ros2-style tools over rmw_zenoh") -> argparse.ArgumentParser:
    """The command's parser: one sub-parser per registered verb."""
    p = Parser(prog=prog, description=description,
               epilog=f"`{prog} VERB -h` shows a verb's options")
    sub = p.add_subparsers(dest="verb", metavar="verb")
    sub.required = True
    plugins = registry.load(groups)
    if not plugins:
        raise CliError(f"no verbs registered in {', '.join(groups)}: is the package installed "
                       "(pip install -e .)?")
    registry.add_verbs(sub, plugins)
    return p


def main(argv: list[str] | None = None, prog: str = "roszen", groups: Sequence[str] = GROUPS,
         description: str = "ros2-style tools over rmw_zenoh") -> int:
    """Run one verb; user errors print one line `<prog> <verb>: <reason>` and return 1."""
    line_buffered()
    argv = sys.argv[1:] if argv is None else list(argv)
    own = registry.own_parser_verb(argv, groups)
    if own is not None:            # a verb with its own parser: the others are not imported
        verb, rest, words = own
        try:
            return verb.run(rest, prog)
        except USER_ERRORS as exc:
            print(f"{prog} {words}: {exc}", file=sys.stderr)
            return 1
        except (KeyboardInterrupt, BrokenPipeError):
            return 0
    try:
        parser = build_parser(prog, groups, description)
        if not argv:
            parser.print_help()
            return 2
        args = parser.parse_args(argv)
        return int(args.func(args) or 0)
    except USER_ERRORS as exc:
        verb = " ".join(a for a in argv[:2] if not a.startswith("-"))
        print(f"{prog} {verb}: {exc}" if verb else f"{prog}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 0
    except BrokenPipeError:
        return 0
