"""`node list | info`, shaped like `ros2 node`."""
from __future__ import annotations

from roszen.cli.common import CliError, make_node


def add_parser(sub) -> None:
    p = sub.add_parser("node", help="inspect nodes")
    v = p.add_subparsers(dest="cmd", metavar="command")
    v.required = True
    ls = v.add_parser("list", help="output a list of available nodes")
    ls.add_argument("-a", "--all", action="store_true", help="show hidden nodes too")
    ls.add_argument("-c", "--count-nodes", action="store_true")
    ls.set_defaults(func=list_cmd)
    info = v.add_parser("info", help="output information about a node")
    info.add_argument("node_name")
    info.set_defaults(func=info_cmd)


def _fqn(name: str, ns: str) -> str:
    return f"{ns.rstrip('/')}/{name}"


def list_cmd(args) -> int:
    node = make_node()
    try:
        names = sorted(_fqn(n, ns) for n, ns in node.get_node_names_and_namespaces())
    finally:
        node.destroy_node()
    if not args.all:
        names = [n for n in names if not n.rsplit("/", 1)[-1].startswith("_")]
    if args.count_nodes:
        print(len(names))
        return 0
    for n in names:
        print(n)
    return 0


def info_cmd(args) -> int:
    target = args.node_name if args.node_name.startswith("/") else "/" + args.node_name
    node = make_node()
    try:
        found = [(n, ns) for n, ns in node.get_node_names_and_namespaces()
                 if _fqn(n, ns) == target]
        if not found:
            raise CliError(f"Unable to find node '{target}'")
        name, ns = found[0]
        graph = node.context.graph
        sections = [
            ("Subscribers", graph.get_subscriber_names_and_types_by_node(name, ns)),
            ("Publishers", graph.get_publisher_names_and_types_by_node(name, ns)),
            ("Service Servers", graph.get_service_names_and_types_by_node(name, ns)),
            ("Service Clients", graph.get_client_names_and_types_by_node(name, ns)),
            ("Action Servers", []),
            ("Action Clients", []),
        ]
    finally:
        node.destroy_node()
    if len(found) > 1:
        print("There are 2 nodes in the graph with the exact name "
              f"\"{target}\". You are seeing information about only one of them.")
    print(target)
    for title, items in sections:
        print(f"  {title}:")
        for topic, types in items:
            print(f"    {topic}: {', '.join(types)}")
    return 0
