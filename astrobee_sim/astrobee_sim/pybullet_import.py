"""pybullet without its chatter: its C code prints "pybullet build time: ..." to stderr when first
imported, and loadSoftBody prints "Nodes: ..", "Links: ..", "Faces: ..", "Tetras: .." to stdout,
into every launch's output (C stdio, not sys.stdout/sys.stderr).

`quiet(prefixes)` runs a block with file descriptors 1 and 2 pointed at temporary files; once C
stdio is flushed and the descriptors restored, every line but those starting with one of the
prefixes is passed on where it was going, and exceptions propagate: real errors stay visible.
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import tempfile
from types import ModuleType
from typing import Iterator

BANNER = (b"pybullet build time:",)
SOFT_BODY = (b"Nodes:", b"Links:", b"Faces:", b"Tetras:")     # loadSoftBody's counts


@contextlib.contextmanager
def quiet(prefixes: tuple[bytes, ...]) -> Iterator[None]:
    """Drop the C-level output lines starting with one of `prefixes` printed inside the block
    (see the module docstring); without usable descriptors 1 and 2 it does nothing."""
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = {fd: os.dup(fd) for fd in (1, 2)}
    except (OSError, ValueError, AttributeError):
        yield
        return
    files = {fd: tempfile.TemporaryFile() for fd in saved}
    try:
        for fd, f in files.items():
            os.dup2(f.fileno(), fd)
        yield
    finally:
        ctypes.CDLL(None).fflush(None)                 # C's buffered output into the files
        for fd, f in files.items():
            os.dup2(saved[fd], fd)
            os.close(saved[fd])
            f.seek(0)
            rest = [ln for ln in f.read().splitlines(keepends=True) if not ln.startswith(prefixes)]
            f.close()
            if rest:
                os.write(fd, b"".join(rest))


def pybullet() -> ModuleType:
    """The pybullet module (imported without its banner the first time)."""
    mod = sys.modules.get("pybullet")
    if mod is None:
        with quiet(BANNER):
            import pybullet as mod
    return mod
