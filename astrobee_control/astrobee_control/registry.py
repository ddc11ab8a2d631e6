"""The controller registry: every control law by name, as the installed packages declare it.

A law is registered with one line in its package's entry points (group `astrobee.controllers`,
as ros2cli finds its verbs), naming a `Controller` object of the law's module:

    [project.entry-points."astrobee.controllers"]
    pd = "astrobee_control.tracking:CONTROLLER"

A Controller holds the law's factory, its parameters with their defaults (the one owner of
them: config/controllers.yaml only holds site overrides), a checker that validates parameters
without building the law, and a line of description. The launcher (`controller:=`,
--show-args), astrobee_lab's Flight and study specs, and the node executables read the laws
from here; nothing else lists them. Transport-free (no roszen, no zenoh).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from importlib.metadata import entry_points
from typing import Any, Callable, Mapping

from astrobee.flight_modes import FlightMode

from .law import ControlLaw, LawFactory
from .mass import MassProperties

GROUP = "astrobee.controllers"
GENERIC_EXECUTABLE = "controller_node"   # runs any registered law: `controller_node <name>`


class UnknownController(ValueError):
    """A controller name no installed package registers (one line naming the known ones)."""


@dataclass(frozen=True)
class Controller:
    """One registered law: name, factory, parameters (name -> default), checker, description.

    `check(params)` gets the complete parameters (defaults, config, given) and raises ValueError
    with one line for a bad value, without building the law (the MPC's would start workers).
    `executable`: the law's own node executable of astrobee_control ('': the generic
    controller_node, which runs any law by name)."""

    name: str
    make_law: LawFactory
    parameters: Mapping[str, Any] = field(default_factory=dict)
    check: Callable[[dict], None] | None = None
    description: str = ""
    executable: str = ""

    @property
    def node_name(self) -> str:
        """The law's node name in a launch: <name>_controller_node."""
        return f"{self.name}_controller_node"

    def params(self, given: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Complete parameters: the defaults, config/controllers.yaml's section, then `given`."""
        from astrobee import config
        return {**self.parameters, **(config.controllers().get(self.name) or {}), **(given or {})}

    def check_params(self, given: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """The complete parameters, checked (ValueError, one line); the law is not built."""
        params = self.params(given)
        if self.check is not None:
            try:
                self.check(params)
            except TypeError as exc:
                raise ValueError(str(exc)) from None
        return params

    def make(self, flight_mode: FlightMode, mass: MassProperties,
             given: Mapping[str, Any] | None = None) -> ControlLaw:
        """The law with complete parameters (ValueError with one line for a bad value)."""
        return self.make_law(flight_mode, mass, self.params(given))


@lru_cache(maxsize=1)
def _entry_points() -> dict[str, Any]:
    """The group's entry points by name, scanned once (~10 ms; refresh() scans again)."""
    return {ep.name: ep for ep in entry_points(group=GROUP)}


@lru_cache(maxsize=None)
def _load(name: str) -> Controller:
    eps = _entry_points()
    if name not in eps:
        raise UnknownController(f"unknown controller {name!r}; known: {', '.join(names())}")
    obj = eps[name].load()
    if not isinstance(obj, Controller) or obj.name != name:
        raise TypeError(f"entry point {GROUP}:{name} ({eps[name].value}) must name a "
                        f"Controller called {name!r}")
    return obj


def names() -> tuple[str, ...]:
    """The registered controller names (sorted; no law module is imported)."""
    return tuple(sorted(_entry_points()))


def get(name: str) -> Controller:
    """The registered law `name` (UnknownController, one line, for a name not registered)."""
    return _load(str(name))


def controllers() -> dict[str, Controller]:
    """Every registered law by name (imports each law's module)."""
    return {n: get(n) for n in names()}


def refresh() -> None:
    """Forget the scanned and loaded entries (after packages were installed or sys.path
    changed)."""
    _entry_points.cache_clear()
    _load.cache_clear()


def choices_text(sep: str = " or ") -> str:
    """The names for a message ('mpc or pd', 'fake, mpc or pd') or, with sep=' | ', a help
    text ('fake | mpc | pd')."""
    n = names()
    if sep != " or " or len(n) < 3:
        return sep.join(n)
    return ", ".join(n[:-1]) + " or " + n[-1]
