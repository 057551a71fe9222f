"""`--set section.key=value` overrides of a scenario document (issue 11).

The value is parsed as a TOML value (`3`, `1.5e-3`, `true`, `"text"`, `[1, 2, 3]`, `{a = 1}`); a bare
word that is not TOML (`--set controller.name=sabatini`) is taken as a string. Dotted paths walk
tables; a number walks an array of tables (`--set spacecraft.0.mass_kg=12`). The overridden
document is then validated exactly like the file, so a bad field or value is reported by the same
code, naming the field.
"""
from __future__ import annotations

import copy
import re
import tomllib
from typing import Any

_BARE = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")


class OverrideError(ValueError):
    """A malformed --set expression (the message names it)."""


def parse_value(text: str) -> Any:
    """A TOML value, or a bare word as a string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        if _BARE.match(text):
            return text
        raise OverrideError(f"value {text!r} is not a TOML value (quote strings: '\"text\"')") from None


def parse_set(expr: str) -> tuple[list[str], Any]:
    """'section.key=value' -> (['section', 'key'], value)."""
    if "=" not in expr:
        raise OverrideError(f"--set {expr!r}: expected section.key=value")
    path, _, raw = expr.partition("=")
    parts = [p.strip() for p in path.strip().split(".")]
    if len(parts) < 2 or not all(parts):
        raise OverrideError(f"--set {expr!r}: the field must be section.key (e.g. run.duration_s=600)")
    try:
        return parts, parse_value(raw.strip())
    except OverrideError as exc:
        raise OverrideError(f"--set {expr!r}: {exc}") from None


def set_path(doc: dict[str, Any], path: str, value: Any) -> dict[str, Any]:
    """A copy of doc with the dotted path set to an already-parsed value (sweep --param)."""
    parts = [p.strip() for p in path.split(".")]
    if len(parts) < 2 or not all(parts):
        raise OverrideError(f"{path!r}: the field must be section.key (e.g. sensing.roe_noise_fraction)")
    return _assign(copy.deepcopy(doc), parts, value, path)


def apply_sets(doc: dict[str, Any], sets: list[str] | tuple[str, ...]) -> dict[str, Any]:
    """A copy of doc with every override applied in order (missing tables are created)."""
    out = copy.deepcopy(doc)
    for expr in sets:
        parts, value = parse_set(expr)
        _assign(out, parts, value, expr)
    return out


def _assign(out: dict[str, Any], parts: list[str], value: Any, expr: str) -> dict[str, Any]:
    node: Any = out
    for i, p in enumerate(parts[:-1]):
        where = ".".join(parts[: i + 1])
        if isinstance(node, list):
            if not p.isdigit() or int(p) >= len(node):
                raise OverrideError(f"--set {expr!r}: {where}: index must be 0..{len(node) - 1}")
            node = node[int(p)]
        elif isinstance(node, dict):
            if p not in node:
                node[p] = {}
            node = node[p]
        else:
            raise OverrideError(f"--set {expr!r}: {where} is a value, not a table")
    last = parts[-1]
    if isinstance(node, list):
        if not last.isdigit() or int(last) >= len(node):
            raise OverrideError(f"--set {expr!r}: index must be 0..{len(node) - 1}")
        node[int(last)] = value
    elif isinstance(node, dict):
        node[last] = value
    else:
        raise OverrideError(f"--set {expr!r}: {'.'.join(parts[:-1])} is a value, not a table")
    return out
