"""YAML written by users (command lines, parameter files): yaml.safe_load whose every failure,
a document nested thousands deep included (RecursionError inside the parser), is one YamlError
line naming what was read."""
from __future__ import annotations

from typing import IO, Any, Union

import yaml

MAX_DEPTH = 100     # nested lists/mappings: far beyond any message or parameter file


class YamlError(ValueError):
    """The text is not YAML we take; the message is one line."""


class YamlTooDeep(YamlError):
    """The YAML nests lists/mappings deeper than MAX_DEPTH (never a plain string either)."""


def _depth(data: Any) -> int:
    """How deeply lists and mappings nest in `data` (iterative: no recursion limit)."""
    deepest, stack = 0, [(data, 1)]
    while stack:
        node, d = stack.pop()
        if isinstance(node, dict):
            children = list(node.keys()) + list(node.values())
        elif isinstance(node, list):
            children = node
        else:
            continue
        deepest = max(deepest, d)
        if d <= MAX_DEPTH:
            stack.extend((c, d + 1) for c in children)
    return deepest


def load(source: Union[str, IO], what: str = "the value") -> Any:
    """safe_load `source`; YamlError "<what> is not valid YAML: ..." (first line of the parser's
    message) or "<what>: YAML nested deeper than 100 levels"."""
    try:
        data = yaml.safe_load(source)
    except RecursionError:
        raise YamlTooDeep(f"{what}: YAML nested deeper than {MAX_DEPTH} levels") from None
    except yaml.YAMLError as exc:
        first = " ".join(str(exc).split())
        raise YamlError(f"{what} is not valid YAML: {first[:200]}") from None
    if _depth(data) > MAX_DEPTH:
        raise YamlTooDeep(f"{what}: YAML nested deeper than {MAX_DEPTH} levels")
    return data
