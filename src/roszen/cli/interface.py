"""`interface list | show TYPE | package PKG | packages`, shaped like `ros2 interface`."""
from __future__ import annotations

from roszen.cli.common import CliError


def add_parser(sub) -> None:
    p = sub.add_parser("interface", help="show information about ROS interfaces")
    v = p.add_subparsers(dest="cmd", metavar="command")
    v.required = True
    ls = v.add_parser("list", help="list all interface types")
    ls.add_argument("-m", "--only-msgs", action="store_true")
    ls.add_argument("-s", "--only-srvs", action="store_true")
    ls.set_defaults(func=list_cmd)
    sh = v.add_parser("show", help="output the interface definition")
    sh.add_argument("type", help="e.g. std_msgs/msg/String")
    sh.add_argument("--no-comments", action="store_true", help="strip comments")
    sh.add_argument("--all-comments", action="store_true", help="comments of nested types too")
    sh.set_defaults(func=show_cmd)
    pk = v.add_parser("package", help="list the interfaces of a package")
    pk.add_argument("package")
    pk.set_defaults(func=package_cmd)
    pks = v.add_parser("packages", help="list packages providing interfaces")
    pks.set_defaults(func=packages_cmd)


def list_cmd(args) -> int:
    from roszen import typestore
    names = typestore.list_types()
    msgs = [n for n in names if "/msg/" in n]
    srvs = [n for n in names if "/srv/" in n]
    if not args.only_srvs:
        print("Messages:")
        for n in msgs:
            print(f"    {n}")
    if not args.only_msgs:
        print("Services:")
        for n in srvs:
            print(f"    {n}")
    if not (args.only_msgs or args.only_srvs):
        print("Actions:")
    return 0


def package_cmd(args) -> int:
    from roszen import typestore
    names = [n for n in typestore.list_types() if n.split("/")[0] == args.package]
    if not names:
        raise CliError(f"Unknown package '{args.package}'")
    print("\n".join(names))
    return 0


def packages_cmd(args) -> int:
    from roszen import typestore
    print("\n".join(sorted({n.split("/")[0] for n in typestore.list_types()})))
    return 0


def resolve_type(name: str, kind: str = "msg") -> str:
    """Full type name, or CliError naming the unknown type (kind: msg | srv | any)."""
    from roszen import typestore
    try:
        full = typestore.normalize_type_name(name)
        if typestore.is_service(full):
            if kind == "msg":
                raise CliError(f"'{name}' is a service type, not a message type")
            typestore.get_service_spec(full)
        else:
            if kind == "srv":
                raise CliError(f"'{name}' is not a known service type")
            typestore.get_spec(full)
    except (typestore.UnknownTypeError, ValueError) as exc:
        if isinstance(exc, CliError):
            raise
        what = "service" if kind == "srv" else "message" if kind == "msg" else "interface"
        raise CliError(f"The passed {what} type '{name}' is invalid ({exc})") from None
    return full


def _strip(line: str) -> str:
    out, quote = [], None
    for ch in line:
        if quote:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif ch == "#":
            break
        out.append(ch)
    return "".join(out).rstrip()


def expand(text: str, package: str, indent: int, comments: bool, all_comments: bool) -> list[str]:
    """Definition lines with nested message types expanded below their field (tab indent)."""
    from roszen import typestore
    out = []
    for raw in text.splitlines():
        code = _strip(raw)
        if not code.strip():
            if comments and (raw.strip() or indent == 0):
                out.append("\t" * indent + raw)
            continue
        out.append("\t" * indent + (raw if comments else code))
        token = code.split()[0]
        if "=" in code.split()[1] if len(code.split()) > 1 else False:
            continue        # constant
        base = token.split("[")[0].split("<=")[0]
        if base in _PRIMITIVES:
            continue
        full = base if "/" in base else f"{package}/{base}"
        if full.count("/") == 1:
            full = full.replace("/", "/msg/")
        if base == "Header":
            full = "std_msgs/msg/Header"
        spec = typestore.get_spec(full)
        out += expand(spec.definition(), full.split("/")[0], indent + 1,
                      all_comments, all_comments)
    return out


_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
               "int32", "uint32", "int64", "uint64", "string", "wstring"}


def show_cmd(args) -> int:
    from roszen import typestore
    full = resolve_type(args.type, "any")
    text = typestore.definition_text(full)
    package = full.split("/")[0]
    comments = not args.no_comments
    if typestore.is_service(full):
        req, _, resp = text.partition("\n---\n") if "\n---\n" in text else text.partition("---\n")
        lines = expand(req, package, 0, comments, args.all_comments) + ["---"] + \
            expand(resp, package, 0, comments, args.all_comments)
    else:
        lines = expand(text, package, 0, comments, args.all_comments)
    print("\n".join(lines))
    return 0
