"""pybullet imported without its banner: its C extension prints "pybullet build time: ..." to the
process's stderr (C stdio, not sys.stderr) when first imported, into every launch's output.

The first import runs with file descriptor 2 pointed at a temporary file; once C stdio is
flushed and the descriptor restored, whatever else was written there is passed on to stderr,
and an import error still raises: only the banner line is dropped.
"""
from __future__ import annotations

import ctypes
import os
import sys
import tempfile
from types import ModuleType

BANNER = b"pybullet build time:"


def pybullet() -> ModuleType:
    """The pybullet module (imported quietly the first time)."""
    mod = sys.modules.get("pybullet")
    if mod is not None:
        return mod
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):     # no usable stderr: nothing to silence
        import pybullet as mod
        return mod
    with tempfile.TemporaryFile() as captured:
        try:
            os.dup2(captured.fileno(), 2)
            import pybullet as mod
        finally:
            ctypes.CDLL(None).fflush(None)            # C's buffered output into the file
            os.dup2(saved, 2)
            os.close(saved)
            captured.seek(0)
            rest = [ln for ln in captured.read().splitlines(keepends=True)
                    if not ln.startswith(BANNER)]
            if rest:
                os.write(2, b"".join(rest))
    return mod
