"""Generated CDR (XCDR1 little endian) serializers: one flat function per message type.

Nested messages are inlined, consecutive scalars whose padding is known at generation time are
packed by one `struct.pack`, and the checks that keep garbage off the wire (numpy dtype/shape,
array lengths, sequence and string bounds) are done inline in the same pass. Any failure raises
and the caller retries through the validating converter (see `cdr.CdrBackend.serializer`).
"""
from __future__ import annotations

import struct
from typing import Any, Callable

import numpy as np

from .spec import FieldType, MsgSpec

_FMT = {"bool": "?", "byte": "B", "char": "B", "uint8": "B", "int8": "b", "int16": "h", "uint16": "H",
        "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q", "float32": "f", "float64": "d"}
_SIZE = {"?": 1, "B": 1, "b": 1, "h": 2, "H": 2, "i": 4, "I": 4, "q": 8, "Q": 8, "f": 4, "d": 8}
_PAD = tuple(bytes(n) for n in range(8))


class SerializeCheckError(ValueError):
    """A field value the generated code refuses to copy as raw bytes (wrong dtype, length...)."""


class _Gen:
    """Emits the body of `ser(m)`; tracks what is known about the write position's alignment."""

    def __init__(self, lookup: Callable[[str], MsgSpec], dtypes: dict) -> None:
        self.lookup, self.dtypes = lookup, dtypes
        self.lines: list[str] = []
        self.ns: dict[str, Any] = {"_PAD": _PAD, "_nd": np.ndarray, "_Bad": SerializeCheckError,
                                   "_u32": struct.Struct("<I").pack}
        self.nvar = 0
        self.static: int | None = 0   # body offset if known at generation time
        self.known = 8                # else: alignment guaranteed for the offset
        self.run: list[tuple[str, str]] = []   # pending (format, expr) of one pack
        self.run_base = (0, 8)        # (offset mod g, g) of the run start
        self.run_len = 0

    def var(self, prefix: str) -> str:
        self.nvar += 1
        return f"{prefix}{self.nvar}"

    def emit(self, line: str, indent: int) -> None:
        self.lines.append("    " * indent + line)

    # -- alignment ------------------------------------------------------------------------
    def flush(self, indent: int) -> None:
        if not self.run:
            return
        fmt = "<" + "".join(f for f, _ in self.run)
        name = self.var("_s")
        self.ns[name] = struct.Struct(fmt).pack
        args = ", ".join(e for _, e in self.run if e)
        self.emit(f"out += {name}({args})", indent)
        b0, g = self.run_base
        end = b0 + self.run_len
        if self.static is not None:
            self.static += self.run_len
        else:
            self.known = g if end % g == 0 else min(g, end & -end)
        self.run, self.run_len = [], 0

    def align(self, a: int, indent: int) -> None:
        """Pad the output (outside any run) to alignment `a`."""
        if a == 1:
            return
        if self.static is not None:
            pad = -self.static % a
            if pad:
                self.emit(f"out += _PAD[{pad}]", indent)
                self.static += pad
        elif self.known < a:
            self.emit(f"out += _PAD[(4 - len(out)) & {a - 1}]", indent)
            self.known = a

    def scalar(self, fmt: str, expr: str, indent: int) -> None:
        a = _SIZE[fmt]
        if self.run:
            b0, g = self.run_base
            if a > g:
                self.flush(indent)
        if not self.run:
            self.align(a, indent)
            self.run_base = (self.static % 8, 8) if self.static is not None else (0, self.known)
        b0, g = self.run_base
        pad = -(b0 + self.run_len) % a
        if pad:
            self.run.append((f"{pad}x", ""))
            self.run_len += pad
        self.run.append((fmt, expr))
        self.run_len += a

    def dynamic(self, known: int) -> None:
        self.static, self.known = None, known

    # -- fields ---------------------------------------------------------------------------
    def message(self, spec: MsgSpec, expr: str, indent: int) -> None:
        from .classes import attr_name
        for f in spec.wire_fields():
            self.field(f.type, f"{expr}.{attr_name(f.name)}", indent)

    def string(self, expr: str, bound: int, indent: int) -> None:
        self.flush(indent)
        b = self.var("b")
        self.emit(f"{b} = {expr}.encode()", indent)
        if bound:
            self.emit(f"if len({expr}) > {bound}: raise _Bad('string longer than its bound {bound}')", indent)
        self.align(4, indent)
        self.emit(f"out += _u32(len({b}) + 1); out += {b}; out += b'\\x00'", indent)
        self.dynamic(1)

    def field(self, t: FieldType, expr: str, indent: int) -> None:
        if t.kind == "scalar":
            if t.is_primitive:
                if t.base in ("string", "wstring"):
                    self.string(expr, t.string_bound, indent)
                else:
                    self.scalar(_FMT[t.base], expr, indent)
            else:
                v = self.var("v")  # a fresh name: the pending pack may still read earlier ones
                self.emit(f"{v} = {expr}", indent)
                self.message(self.lookup(t.base), v, indent)
            return
        v = self.var("v")
        self.flush(indent)
        self.emit(f"{v} = {expr}", indent)
        if t.kind == "array":
            self.emit(f"if len({v}) != {t.size}: raise _Bad('expected {t.size} elements, got %d' % len({v}))", indent)
        else:
            if t.kind == "bseq":
                self.emit(f"if len({v}) > {t.size}: raise _Bad('at most {t.size} elements, got %d' % len({v}))",
                          indent)
            self.align(4, indent)
            self.emit(f"out += _u32(len({v}))", indent)
            if self.static is not None:
                self.static += 4
        if t.is_primitive and t.base not in ("string", "wstring"):
            fmt = _FMT[t.base]
            size = _SIZE[fmt]
            dt = self.var("_t")
            self.ns[dt] = self.dtypes[t.base]
            self.emit(f"if type({v}) is not _nd or {v}.dtype != {dt} or {v}.ndim != 1: "
                      f"raise _Bad('needs a 1-d {t.base} array')", indent)
            if t.kind == "array":
                self.align(size, indent)
                self.emit(f"out += {v}.data", indent)   # C-contiguity is checked by .data's buffer export
                if self.static is not None:
                    self.static += size * t.size
                else:
                    self.known = min(self.known, size) if t.size else self.known
            else:
                if size > 1:
                    self.emit(f"if len({v}): out += _PAD[(4 - len(out)) & {size - 1}]", indent)
                self.emit(f"out += {v}.data", indent)
                self.dynamic(min(size, 4))
            return
        # strings or messages: per element, alignment unknown at the start of each
        e = self.var("e")
        self.emit(f"for {e} in {v}:", indent)
        self.dynamic(1)
        if t.is_primitive:
            self.string(e, t.string_bound, indent + 1)
        else:
            self.message(self.lookup(t.base), e, indent + 1)
        self.flush(indent + 1)
        self.dynamic(1)


def make_serializer(spec: MsgSpec, lookup: Callable[[str], MsgSpec], dtypes: dict) -> Callable[[Any], bytes]:
    """`ser(msg) -> bytes` (with the 00 01 00 00 header) for messages of `spec`."""
    g = _Gen(lookup, dtypes)
    g.message(spec, "m", 1)
    g.flush(1)
    code = ("def ser(m):\n    out = bytearray(b'\\x00\\x01\\x00\\x00')\n" + "\n".join(g.lines)
            + "\n    return bytes(out)\n")
    exec(compile(code, f"<roszen serializer {spec.name}>", "exec"), g.ns)  # noqa: S102
    fn = g.ns["ser"]
    fn.source = code
    return fn
