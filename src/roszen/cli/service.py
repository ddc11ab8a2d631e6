"""`service list | type | find | call`, shaped like `ros2 service`."""
from __future__ import annotations

import time

from roszen.cli.common import (CliError, fq_name, make_node, parse_yaml_values, positive_float,
                               spin_until)


def add_parser(sub) -> None:
    p = sub.add_parser("service", help="inspect and call services")
    v = p.add_subparsers(dest="cmd", metavar="command")
    v.required = True
    ls = v.add_parser("list", help="output a list of available services")
    ls.add_argument("-t", "--show-types", action="store_true")
    ls.add_argument("-c", "--count-services", action="store_true")
    ls.set_defaults(func=list_cmd)
    ty = v.add_parser("type", help="output a service's type")
    ty.add_argument("service_name")
    ty.set_defaults(func=type_cmd)
    find = v.add_parser("find", help="services of a given type")
    find.add_argument("service_type")
    find.set_defaults(func=find_cmd)
    call = v.add_parser("call", help="call a service")
    call.add_argument("service_name")
    call.add_argument("service_type")
    call.add_argument("values", nargs="?", default="{}", help="YAML of the request fields")
    call.add_argument("-r", "--rate", type=positive_float, default=None,
                      help="repeat the call at this rate (Hz)")
    call.add_argument("--timeout", type=positive_float, default=10.0,
                      help="seconds to wait for the service and for each response (default 10)")
    call.set_defaults(func=call_cmd)


def _servers(node) -> list[tuple[str, list[str]]]:
    from roszen.wire import SERVICE
    out: dict[str, set[str]] = {}
    for e in node.context.graph.entities(SERVICE):
        out.setdefault(e.name, set()).add(e.ros_type)
    return sorted((k, sorted(v)) for k, v in out.items())


def list_cmd(args) -> int:
    node = make_node()
    try:
        services = node.get_service_names_and_types()
    finally:
        node.destroy_node()
    if args.count_services:
        print(len(services))
        return 0
    for name, types in services:
        print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return 0


def type_cmd(args) -> int:
    name = fq_name(args.service_name)
    node = make_node()
    try:
        types = dict(node.get_service_names_and_types()).get(name)
    finally:
        node.destroy_node()
    if not types:
        raise CliError(f"Unknown service '{name}'")
    print("\n".join(types))
    return 0


def find_cmd(args) -> int:
    node = make_node()
    try:
        for name, types in node.get_service_names_and_types():
            if args.service_type in types:
                print(name)
    finally:
        node.destroy_node()
    return 0


def call_cmd(args) -> int:
    from roszen import typestore
    from roszen.cli.interface import resolve_type
    from roszen.node import ServiceError
    from roszen.types.convert import from_dict
    name = fq_name(args.service_name)
    srv_type = resolve_type(args.service_type, "srv")
    Req = typestore.request_class(srv_type)
    request = parse_yaml_values(args.values, srv_type,
                                lambda d: from_dict(Req, d))
    node = make_node()
    try:
        client = node.create_client(srv_type, name)
        if not client.service_is_ready():
            print("waiting for service to become available...")
            if not client.wait_for_service(timeout_sec=args.timeout):
                servers = dict(_servers(node)).get(name)
                if servers:
                    raise CliError(f"service '{name}' has type {', '.join(servers)}, "
                                   f"not {srv_type}")
                raise CliError(f"service '{name}' not available after {args.timeout:g} s")
        while True:
            print(f"requester: making request: {request!r}\n")
            try:
                response = client.call(request, timeout_sec=args.timeout)
            except TimeoutError:
                raise CliError(f"service '{name}' did not respond within {args.timeout:g} s") \
                    from None
            except ServiceError as exc:
                raise CliError(f"service call failed: {exc}") from None
            print(f"response:\n{response!r}\n")
            if args.rate is None:
                return 0
            end = time.monotonic() + 1.0 / args.rate
            spin_until(node, lambda: time.monotonic() >= end)
    finally:
        node.destroy_node()
