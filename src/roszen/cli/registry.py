"""CLI verbs as entry-point plugins (as ros2cli): a package adds a verb with one line in its
pyproject.toml, and `-h` lists it.

Groups: `roszen.verbs` (the ros2-style verbs), `astrobee.verbs` (the astrobee command's own) and
`roszen.<verb>.verbs` for the sub-verbs of a verb (`roszen.bag.verbs`: record, play, ...). An
entry point names either a function `add_parser(subparsers)` that adds an argparse sub-parser
whose defaults carry `func(args) -> int`, or a `Verb` for a verb with its own argument parser
(it gets the rest of the command line).
"""
from __future__ import annotations

import argparse
import importlib
import inspect
import sys
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Callable, Iterable, Optional, Union


@dataclass(frozen=True)
class Verb:
    """A verb that parses its own arguments: `target` is "module:function", called with the
    argument list after the verb and returning the exit status; importing it waits until the
    verb runs, so `-h` stays fast."""
    help: str
    target: str

    def run(self, argv: list[str], prog: str = "roszen") -> int:
        """Call the target with argv (and `prog=`, the command's name, when it takes one)."""
        module, _, func = self.target.partition(":")
        fn = getattr(importlib.import_module(module), func)
        takes_prog = "prog" in inspect.signature(fn).parameters
        return int((fn(argv, prog=prog) if takes_prog else fn(argv)) or 0)


Plugin = Union[Verb, Callable[[argparse._SubParsersAction], None]]


def sub_group(verb: str) -> str:
    """The entry-point group of `verb`'s sub-verbs."""
    return f"roszen.{verb}.verbs"


def _entries(groups: Iterable[str]) -> dict:
    """name -> entry point in `groups` (a later group's name wins)."""
    found: dict = {}
    for group in groups:
        for ep in entry_points(group=group):
            found[ep.name] = ep
    return found


def _load(ep) -> Optional[Plugin]:
    """The plugin an entry point names; a broken one is reported in one line and skipped."""
    try:
        return ep.load()
    except Exception as exc:  # noqa: BLE001 - a broken plugin must not take the other verbs down
        print(f"warning: verb {ep.name!r} ({ep.value}) cannot be loaded: {exc}", file=sys.stderr)
        return None


def load(groups: Iterable[str]) -> dict[str, Plugin]:
    """name -> plugin of every entry point in `groups`, sorted by name."""
    loaded = {name: _load(ep) for name, ep in sorted(_entries(groups).items())}
    return {name: plugin for name, plugin in loaded.items() if plugin is not None}


def add_verbs(sub: argparse._SubParsersAction, plugins: dict[str, Plugin]) -> None:
    """Add each plugin's sub-parser; a `Verb` gets one that passes the rest of the line on."""
    for name, plugin in plugins.items():
        if isinstance(plugin, Verb):
            p = sub.add_parser(name, help=plugin.help, add_help=False)
            p.add_argument("argv", nargs=argparse.REMAINDER)
            p.set_defaults(func=lambda args, v=plugin: v.run(args.argv, p.prog.split()[0]))
        else:
            plugin(sub)


def add_sub_verbs(parser: argparse.ArgumentParser, verb: str) -> None:
    """The sub-verbs of `verb` (its entry-point group) as sub-parsers of `parser`."""
    v = parser.add_subparsers(dest="cmd", metavar="command")
    v.required = True
    add_verbs(v, load([sub_group(verb)]))


def own_parser_verb(argv: list[str], groups: Iterable[str]
                    ) -> Optional[tuple[Verb, list[str], str]]:
    """(verb, its arguments, its words) when argv names a `Verb` (or a verb's `Verb` sub-verb):
    it runs without building the other verbs' parsers."""
    if not argv:
        return None
    ep = _entries(groups).get(argv[0])
    top = _load(ep) if ep is not None else None
    if isinstance(top, Verb):
        return top, argv[1:], argv[0]
    if top is not None and len(argv) > 1:
        sub_ep = _entries([sub_group(argv[0])]).get(argv[1])
        sub = _load(sub_ep) if sub_ep is not None else None
        if isinstance(sub, Verb):
            return sub, argv[2:], f"{argv[0]} {argv[1]}"
    return None
