"""`param list | get | set | describe | dump`, shaped like `ros2 param`, over the nodes' parameter services."""
from __future__ import annotations

from typing import Any

from roszen.cli.common import CliError, make_node, positive_float

# ParameterType value -> the word `ros2 param get` prints ("Double value is: 1.5")
TYPE_WORDS = {1: "Boolean", 2: "Integer", 3: "Double", 4: "String", 5: "Byte",
              6: "Boolean", 7: "Integer", 8: "Double", 9: "String"}


def add_parser(sub) -> None:
    p = sub.add_parser("param", help="get, set, list and dump the parameters of a node")
    v = p.add_subparsers(dest="cmd", metavar="command")
    v.required = True
    ls = v.add_parser("list", help="output the parameter names of a node (of every node without "
                      "NODE)")
    ls.add_argument("node_name", nargs="?")
    ls.add_argument("--param-type", action="store_true", help="print each parameter's type")
    ls.set_defaults(func=list_cmd)
    get = v.add_parser("get", help="print a parameter's value")
    get.add_argument("node_name")
    get.add_argument("parameter_name")
    get.add_argument("--hide-type", action="store_true", help="print only the value")
    get.set_defaults(func=get_cmd)
    st = v.add_parser("set", help="set a parameter (the value is parsed as YAML)")
    st.add_argument("node_name")
    st.add_argument("parameter_name")
    st.add_argument("value")
    st.set_defaults(func=set_cmd)
    desc = v.add_parser("describe", help="print parameters' descriptors: type, read-only, "
                        "range and constraints")
    desc.add_argument("node_name")
    desc.add_argument("parameter_names", nargs="+")
    desc.set_defaults(func=describe_cmd)
    dump = v.add_parser("dump", help="print a node's parameters as a ROS 2 params file (YAML)")
    dump.add_argument("node_name")
    dump.set_defaults(func=dump_cmd)
    for q in (ls, get, st, desc, dump):
        q.add_argument("--timeout", type=positive_float, default=5.0,
                       help="seconds to wait for the node's parameter services (default 5)")


def _fqn(name: str) -> str:
    name = name.strip()
    if not name or name == "/":
        raise CliError("empty node name")
    return name if name.startswith("/") else "/" + name


def _nodes(node) -> list[str]:
    return sorted(f"{ns.rstrip('/')}/{n}" for n, ns in node.get_node_names_and_namespaces())


class _Session:
    """A hidden CLI node plus ParameterClients for the nodes asked about."""

    def __init__(self, timeout: float) -> None:
        self.node = make_node("_ros2cli_param")
        self.timeout = timeout

    def client(self, target: str):
        from roszen.param_services import ParameterClient
        if target not in _nodes(self.node):
            raise CliError(f"Node not found: '{target}'")
        cli = ParameterClient(self.node, target)
        if not cli.wait(self.timeout):
            raise CliError(f"node '{target}' has no parameter services "
                           f"(none answered within {self.timeout:g} s)")
        return cli

    def call(self, fn, *args):
        try:
            return fn(*args, timeout_sec=self.timeout)
        except TimeoutError:
            raise CliError(f"the parameter service did not answer within {self.timeout:g} s") \
                from None

    def close(self) -> None:
        self.node.destroy_node()


def _types(session, cli, names: list[str]) -> dict[str, int]:
    return {d.name: int(d.type) for d in session.call(cli.describe, names)}


def _plain(value: Any) -> Any:
    """A parameter value as plain Python (YAML-dumpable)."""
    if isinstance(value, bytes):
        return list(value)
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def list_cmd(args) -> int:
    s = _Session(args.timeout)
    try:
        targets = [_fqn(args.node_name)] if args.node_name else \
            [n for n in _nodes(s.node) if not n.rsplit("/", 1)[-1].startswith("_")]
        for target in targets:
            try:
                cli = s.client(target)
            except CliError:
                if args.node_name:
                    raise
                continue                    # a node without parameter services: skipped
            names = sorted(s.call(cli.list))
            types = _types(s, cli, names) if args.param_type and names else {}
            if not args.node_name:
                print(f"{target}:")
            for n in names:
                t = types.get(n, 0)
                word = TYPE_WORDS.get(t, "").lower() + (" array" if t >= 5 else "")
                print(f"  {n}" + (f" (type: {word})" if args.param_type and t else ""))
    finally:
        s.close()
    return 0


def get_cmd(args) -> int:
    target = _fqn(args.node_name)
    s = _Session(args.timeout)
    try:
        cli = s.client(target)
        (value,) = s.call(cli.get, [args.parameter_name])
        if value is None:
            raise CliError(f"Parameter not set: '{args.parameter_name}' on node '{target}'")
        ptype = _types(s, cli, [args.parameter_name]).get(args.parameter_name, 0)
    finally:
        s.close()
    value = _plain(value)
    if args.hide_type:
        print(value)
    elif ptype >= 5:
        print(f"{TYPE_WORDS.get(ptype, '')} values are: {value}")
    else:
        print(f"{TYPE_WORDS.get(ptype, '')} value is: {value}")
    return 0


def describe_cmd(args) -> int:
    """As `ros2 param describe`: each parameter's type and constraints."""
    target = _fqn(args.node_name)
    s = _Session(args.timeout)
    try:
        descs = s.call(s.client(target).describe, list(args.parameter_names))
    finally:
        s.close()
    for d in descs:
        t = int(d.type)
        if not t:
            raise CliError(f"Parameter not set: '{d.name}' on node '{target}'")
        print(f"Parameter name: {d.name}")
        print(f"  Type: {TYPE_WORDS.get(t, '').lower()}" + (" array" if t >= 5 else ""))
        if d.description:
            print(f"  Description: {d.description}")
        print("  Constraints:")
        if d.read_only:
            print("    Read only: true")
        for rng in list(d.floating_point_range) + list(d.integer_range):
            print(f"    Min value: {rng.from_value:g}\n    Max value: {rng.to_value:g}")
        if d.additional_constraints:
            print(f"    Additional constraints: {d.additional_constraints}")
    return 0


def parse_value(text: str) -> Any:
    """The command line's value as `ros2 param set` reads it (YAML: 1 int, 1.0 double, true)."""
    from roszen import yamltext
    try:
        value = yamltext.load(text)
    except yamltext.YamlTooDeep as exc:
        raise CliError(str(exc)) from None
    except yamltext.YamlError:
        return text
    if value is None:
        return text
    if isinstance(value, list):
        kinds = {type(v) for v in value}
        if kinds == {int, float}:
            value = [float(v) for v in value]
        elif len(kinds) > 1:
            raise CliError(f"array values must all have one type, got {text!r}")
        elif kinds and not kinds <= {bool, int, float, str}:
            raise CliError(f"not a parameter value: {text!r}")
    elif not isinstance(value, (bool, int, float, str)):
        raise CliError(f"not a parameter value (a mapping?): {text!r}")
    return value


def set_cmd(args) -> int:
    target = _fqn(args.node_name)
    value = parse_value(args.value)
    s = _Session(args.timeout)
    try:
        cli = s.client(target)
        ((ok, reason),) = s.call(cli.set, {args.parameter_name: value})
    finally:
        s.close()
    if not ok:
        raise CliError(f"Setting parameter failed: {reason or 'rejected by the node'}")
    print("Set parameter successful")
    return 0


def dump_cmd(args) -> int:
    import yaml
    target = _fqn(args.node_name)
    s = _Session(args.timeout)
    try:
        cli = s.client(target)
        names = sorted(s.call(cli.list))
        values = s.call(cli.get, names) if names else []
    finally:
        s.close()
    params = {n: _plain(v) for n, v in zip(names, values) if v is not None}
    print(yaml.safe_dump({target: {"ros__parameters": params}}, sort_keys=False,
                         default_flow_style=None), end="")
    return 0
