"""Render the registry's tables into the docs, between `<!-- claims:ID -->` and `<!-- /claims -->`."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Callable, Mapping

from swarmhil.claims.model import PLACEHOLDER, Claim, Table, Value, Values

ROOT = Path(__file__).resolve().parent.parent
BLOCK = re.compile(r"(<!-- claims:([a-z0-9\-]+) -->\n)(.*?)(<!-- /claims -->)", re.S)


def fill(template: str, claims: Mapping[str, Claim], values: Values) -> str:
    """A cell template with each `{id}` / `{id:spec}` replaced by the claim's value, formatted."""
    def one(m: re.Match[str]) -> str:
        c = claims[m.group(1)]
        return c.render(values.get(c.id, c.value), m.group(2) or None)

    return PLACEHOLDER.sub(one, template)


def row_values(table: Table, claims: Mapping[str, Claim], values: Values | None = None) -> list[dict[str, Value]]:
    """Per row, the claims' values it shows (recorded ones unless `values` has them)."""
    values = values or {}
    out = []
    for row in table.rows:
        ids = [m.group(1) for cell in row.cells for m in PLACEHOLDER.finditer(cell)]
        out.append({i: values.get(i, claims[i].value) for i in ids})
    return out


def verdicts(table: Table, claims: Mapping[str, Claim], values: Values | None = None) -> list[str | None]:
    """The verdict of each row, computed from the values (recorded ones unless given)."""
    vals = {c: values.get(c, claims[c].value) for c in claims} if values else {c: claims[c].value for c in claims}
    return [_verdict(row.verdict, vals) if row.verdict else None for row in table.rows]


def _verdict(fn: Callable[[Values], str], vals: Values) -> str:
    """The row's verdict; "(not recorded)" when a value it reads is not recorded yet (None). A verdict
    that reads an id the registry does not hold is a bug in the table, raised, not hidden."""
    try:
        return fn(vals)
    except KeyError as exc:
        raise KeyError(f"a verdict reads {exc.args[0]!r}, which is not a claim of the registry") from None
    except TypeError:  # a value not recorded yet
        return "(not recorded)"


def render_table(table: Table, claims: Mapping[str, Claim], values: Values | None = None) -> str:
    """The markdown table, from the recorded values (or `values`), verdicts computed."""
    vals = dict(values or {})
    align = table.align or ("---",) * len(table.header)
    lines = ["| " + " | ".join(table.header) + " |", "|" + "|".join(align) + "|"]
    for row, verdict in zip(table.rows, verdicts(table, claims, vals)):
        cells = [fill(c, claims, vals) for c in row.cells]
        if table.verdict_col is not None:
            cells.insert(table.verdict_col, verdict or "")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def blocks(text: str) -> dict[str, str]:
    """The marked tables of a doc: marker id -> the text between the markers."""
    return {m.group(2): m.group(3) for m in BLOCK.finditer(text)}


def rewrite(text: str, tables: Mapping[str, Table], claims: Mapping[str, Claim], values: Values | None = None) -> str:
    """The doc with every marked table that the registry knows re-rendered."""
    def one(m: re.Match[str]) -> str:
        t = tables.get(m.group(2))
        return m.group(0) if t is None else m.group(1) + render_table(t, claims, values) + m.group(4)

    return BLOCK.sub(one, text)


def write_docs(tables: Mapping[str, Table], claims: Mapping[str, Claim], root: Path = ROOT) -> list[str]:
    """`swarmhil claims --write`: re-render every marked table in place; the docs changed."""
    changed = []
    for doc in sorted({t.doc for t in tables.values()}):
        p = root / doc
        old = p.read_text()
        new = rewrite(old, {k: t for k, t in tables.items() if t.doc == doc}, claims)
        if new != old:
            p.write_text(new)
            changed.append(doc)
    return changed


def doc_drift(tables: Mapping[str, Table], claims: Mapping[str, Claim], root: Path = ROOT) -> list[str]:
    """Every registry table missing from its doc or differing from what the registry renders."""
    out = []
    texts = {doc: (root / doc).read_text() for doc in {t.doc for t in tables.values()}}
    for tid, t in tables.items():
        got = blocks(texts[t.doc]).get(tid)
        if got is None:
            out.append(f"{t.doc}: no <!-- claims:{tid} --> block")
        elif got != render_table(t, claims):
            out.append(f"{t.doc}: the table {tid} differs from the registry (`swarmhil claims --write`)")
    return out


def doc_line(table: Table, row_index: int, root: Path = ROOT) -> int | None:
    """The line of the doc (1-based) that holds a row of a marked table: the marker's line + 3
    (header, separator, then the rows)."""
    lines = (root / table.doc).read_text().splitlines()
    marker = next((i + 1 for i, line in enumerate(lines) if line.strip() == f"<!-- claims:{table.id} -->"), None)
    return None if marker is None else marker + 3 + row_index
