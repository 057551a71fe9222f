"""Numbers in the docs' prose: every measured-looking number outside the rendered claims tables
either comes from the registry or is marked as a parameter, a paper's figure or a defined constant
(docs/claims.md "Numbers in prose").

A *measured-looking* number is a number with a unit (12.3 s, 2.1 m/s, 54 MB, 37 %) or a ratio
(4.5x, 4.5×, 3 times). Not scanned: the rendered tables (`<!-- claims:ID -->` ... `<!-- /claims -->`),
fenced and indented code blocks, inline code, HTML comments and link targets.

Marks (HTML comments, invisible in the rendered page):

- `<!-- param -->`, `<!-- paper -->`, `<!-- def -->` (an optional reason after a colon) right after a
  number (`20 h<!-- param -->`) covers that number; after anything else (a space, a word, a
  bracket) it covers the numbers of its line before it, back to the previous mark on that line; a
  mark on a line of its own covers the block that follows it (up to the next blank line: a
  paragraph or a table);
- `<!-- claim:ID -->` (or `<!-- claim:ID:SPEC -->`, SPEC a format of `Claim.render`) right after a
  number says that number is the registry's claim ID: the check fails when the number is not what the
  registry renders, and `swarmhil claims --write` rewrites it.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Mapping

from swarmhil.claims.model import Claim

ROOT = Path(__file__).resolve().parent.parent
BASELINE = Path(__file__).resolve().parent / "prose_baseline.json"
KINDS = ("param", "paper", "def")

# the docs a reader meets: every docs/*.md and README.md
def docs(root: Path = ROOT) -> list[Path]:
    """The scanned docs, README.md first."""
    return [root / "README.md"] + sorted((root / "docs").glob("*.md"))


_NUM = r"(?<![\w.\-+/])[-−+±~≈]?(?:\d{1,3}(?:[,  ]\d{3})+|\d+)(?:\.\d+)?(?:e[-−+]?\d+)?"
_UNITS = (
    # time
    r"ms|µs|us|ns|s|sec|seconds?|min|minutes?|h|hours?|days?"
    # length, speed, acceleration
    r"|km/s|m/s²|m/s\^2|m/s2|mm/s²|mm/s\^2|µm/s²|mm/s|cm/s|m/s|km|mm|cm|µm|m"
    # frequency, data, rates per second
    r"|kHz|MHz|GHz|Hz|KiB|MiB|GiB|kB|KB|MB|GB|TB|bytes?|B|[A-Za-z]+/s"
    # force, mass, angle, power
    r"|mN|µN|uN|N|kg|mrad|µrad|rad|deg|degrees?|arcsec|arcmin|°|mW|W"
)
# a number, optionally a space, then a unit not followed by a word character (so "3 sc", "5 more"
# are not units), or a ratio (4.5x, 4.5×, 3 times), or a percentage
_RANGE = r"(?:\s?[-–]\s?\d+(?:\.\d+)?)?"  # 23.7-30.0 s, 3-4 min: one number
NUMBER = re.compile(
    rf"(?P<num>{_NUM}{_RANGE})(?:(?P<ratio>[x×](?![\w])| ?× ?(?=\D)| times\b)|(?P<pct> ?%)"
    rf"|[  ]?(?P<unit>(?:{_UNITS}))(?![\w²^/]))"
    rf"|(?<![\w.])(?:×\d+(?:\.\d+)?|x\d+\.\d+)(?![\w.*'])"  # ×2.58, x1.57 (x2 alone is a variable)
)
ANY_NUMBER = re.compile(_NUM)
MARK = re.compile(r"<!--\s*(param|paper|def)\b[^>]*?-->")
CLAIM_REF = re.compile(r"<!--\s*claim:([a-z0-9][a-z0-9_.\-]*?)(?::([^\s>]+))?\s*-->")
COMMENT = re.compile(r"<!--.*?-->")
# rendered blocks, each with the pattern that ends it: the claims tables, and docs/determinism.md's
# kernel-drift table (rendered from docs/data/kernel-drift by bench/kernel_drift.py, checked by
# tests/test_determinism_doc.py)
RENDERED = (
    (re.compile(r"^\s*<!-- claims:[a-z0-9\-]+ -->\s*$"), re.compile(r"^\s*<!-- /claims -->\s*$")),
    (re.compile(r"^\s*<!-- kernel-drift table[^>]*-->\s*$"), re.compile(r"^\s*<!-- /kernel-drift table -->\s*$")),
)
FENCE = re.compile(r"^\s*(```|~~~)")
INDENTED = re.compile(r"^(?: {4}|\t)")
LIST_ITEM = re.compile(r"^(?:[-*+]|\d+[.)])\s")
INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1")
LINK_TARGET = re.compile(r"\]\([^)]*\)|<https?://[^>]*>|https?://\S+")


@dataclass(frozen=True)
class Hit:
    """One unmarked measured-looking number: where, and the text that matched."""

    doc: str
    line: int
    text: str

    def __str__(self) -> str:
        return f"{self.doc}:{self.line}: {self.text}"


@dataclass(frozen=True)
class Ref:
    """An inline claim reference: the number it follows, the claim id and the optional format."""

    doc: str
    line: int
    number: str | None
    id: str
    spec: str | None


def _blank(s: str) -> str:
    """Same length, nothing scannable (keeps the columns of what is left)."""
    return " " * len(s)


def prose_lines(text: str) -> Iterator[tuple[int, str, bool]]:
    """(line number, the line with code, comments other than marks and link targets blanked, whether
    a block mark covers it) for each line outside rendered tables, fenced code and indented code (a
    block indented by four spaces after a blank line that does not continue a list)."""
    closing: re.Pattern[str] | None = None  # what ends the fenced code or rendered table the line is in
    covered = False  # inside the block after a mark that stands on its own line
    blank_before = True  # the previous line is blank (or the text starts)
    in_list = False  # the last block that started at the margin was a list item
    in_indented = False  # inside an indented code block
    for n, line in enumerate(text.splitlines(), 1):
        if closing is not None:
            if closing.match(line):
                closing = None
            continue
        opened = FENCE if FENCE.match(line) else next((end for start, end in RENDERED if start.match(line)), None)
        if opened is not None:
            closing = opened
            continue
        if not line.strip():
            covered = False
            blank_before = True
            continue
        indented = INDENTED.match(line) is not None
        in_indented = indented and (in_indented or (blank_before and not in_list))
        blank_before = False
        if not line[:1].isspace():
            in_list = LIST_ITEM.match(line) is not None
        if in_indented:
            continue
        stripped = COMMENT.sub("", line).strip()
        if not stripped and MARK.search(line):
            covered = True
            continue
        line = INLINE_CODE.sub(lambda m: _blank(m.group(0)), line)
        line = LINK_TARGET.sub(lambda m: _blank(m.group(0)), line)
        line = COMMENT.sub(lambda m: m.group(0) if MARK.fullmatch(m.group(0)) or CLAIM_REF.fullmatch(m.group(0))
                           else _blank(m.group(0)), line)
        yield n, line, covered


def scan(text: str, doc: str) -> tuple[list[Hit], list[Ref]]:
    """The unmarked measured-looking numbers of a doc's prose and its inline claim references."""
    hits: list[Hit] = []
    refs: list[Ref] = []
    for n, line, covered in prose_lines(text):
        # the line in segments ending at each mark or claim reference; the rest has no mark
        pos = 0
        stops = sorted([(m.start(), m.end(), None) for m in MARK.finditer(line)]
                       + [(m.start(), m.end(), m) for m in CLAIM_REF.finditer(line)])
        for start, end, ref in stops + [(len(line), len(line), None)]:
            seg = line[pos:start]
            marked = start < len(line) and ref is None
            found = list(NUMBER.finditer(seg))
            if marked and found and found[-1].end() == len(seg):
                # a mark right after a number covers that number alone
                found, marked = found[:-1], False
            if ref is not None:
                anyn = list(ANY_NUMBER.finditer(seg))
                last = anyn[-1] if anyn else None
                refs.append(Ref(doc, n, last.group(0).lstrip("~≈±+") if last else None, ref.group(1), ref.group(2)))
                # the referenced number is covered; others before it in the segment are not
                found = [m for m in found if last is None or not m.start() <= last.start() < m.end()]
            if not marked and not covered:
                hits += [Hit(doc, n, m.group(0).strip()) for m in found]
            pos = end
    return hits, refs


def _rel(p: Path, root: Path) -> str:
    return p.relative_to(root).as_posix()


def unmarked(root: Path = ROOT) -> dict[str, list[Hit]]:
    """Per doc, its unmarked measured-looking numbers (docs with none are left out)."""
    out = {}
    for p in docs(root):
        hits, _ = scan(p.read_text(), _rel(p, root))
        if hits:
            out[_rel(p, root)] = hits
    return out


def _normal(s: str) -> str:
    """A number as printed, for comparison: thousands separators and the minus sign unified."""
    return re.sub(r"(?<=\d)[,  ](?=\d{3})", "", s).replace("−", "-")


def ref_errors(claims: Mapping[str, Claim], root: Path = ROOT) -> list[str]:
    """One line per inline claim reference that names no claim or follows another number than the
    claim renders."""
    out = []
    for p in docs(root):
        for r in scan(p.read_text(), _rel(p, root))[1]:
            c = claims.get(r.id)
            if c is None:
                out.append(f"{r.doc}:{r.line}: <!-- claim:{r.id} --> is not a claim of the registry")
            elif r.number is None:
                out.append(f"{r.doc}:{r.line}: <!-- claim:{r.id} --> follows no number")
            elif _normal(r.number) != _normal(c.render(None, r.spec)):
                out.append(f"{r.doc}:{r.line}: {r.number} is not the registry's {r.id} = {c.render(None, r.spec)} "
                           "(`swarmhil claims --write`)")
    return out


def rewrite_refs(text: str, claims: Mapping[str, Claim]) -> str:
    """The doc with the number before each inline claim reference replaced by the registry's value
    (lines inside fenced code and rendered tables are left alone)."""
    lines = text.split("\n")
    prose = {n for n, _, _ in prose_lines(text)}
    for i, line in enumerate(lines):
        if i + 1 not in prose or "claim:" not in line:
            continue

        out, pos = [], 0
        for m in CLAIM_REF.finditer(line):
            c = claims.get(m.group(1))
            seg = line[pos:m.start()]
            last = list(ANY_NUMBER.finditer(seg))
            if c is not None and c.value is not None and last:
                k = last[-1]
                num = k.group(0)
                lead = num[: len(num) - len(num.lstrip("~≈±+"))]
                seg = seg[: k.start()] + lead + c.render(None, m.group(2)) + seg[k.end():]
            out.append(seg + m.group(0))
            pos = m.end()
        lines[i] = "".join(out) + line[pos:]
    return "\n".join(lines)


def write_refs(claims: Mapping[str, Claim], root: Path = ROOT) -> list[str]:
    """Rewrite the inline claim references' numbers in place; the docs changed."""
    changed = []
    for p in docs(root):
        old = p.read_text()
        new = rewrite_refs(old, claims)
        if new != old:
            p.write_text(new)
            changed.append(_rel(p, root))
    return changed


def heading_marks(root: Path = ROOT) -> list[str]:
    """One line per mark or claim reference on a heading line: a heading's text is its anchor and
    what claims/coverage.py looks for, so a mark goes on the line before it (a mark alone on a line
    covers the block that follows: the heading)."""
    out = []
    for p in docs(root):
        for n, line, _ in prose_lines(p.read_text()):
            if line.startswith("#") and (MARK.search(line) or CLAIM_REF.search(line)):
                out.append(f"{_rel(p, root)}:{n}: a mark on a heading line; put it on the line before")
    return out


def baseline(path: Path = BASELINE) -> dict[str, int]:
    """Per doc, how many unmarked numbers it may still hold (a count that may only go down)."""
    return json.loads(path.read_text()) if path.exists() else {}


def baseline_errors(found: Mapping[str, list[Hit]], allowed: Mapping[str, int]) -> list[str]:
    """One line per doc whose count of unmarked numbers differs from its baseline: more is a failure
    (a new number to convert, mark or remove); fewer means the baseline must come down to it."""
    out = []
    for doc in sorted(set(found) | set(allowed)):
        n, cap = len(found.get(doc, [])), allowed.get(doc, 0)
        if n > cap:
            out.append(f"{doc}: {n} unmarked numbers in prose, {cap} allowed: "
                       + "; ".join(f"{h.line}: {h.text}" for h in found[doc]))
        elif n < cap:
            out.append(f"{doc}: {n} unmarked numbers, baseline {cap}: lower it (`swarmhil claims --prose --lower-baseline`)")
    return out


def lower_baseline(found: Mapping[str, list[Hit]], path: Path = BASELINE) -> dict[str, int]:
    """Each doc's baseline lowered to its count now (never raised); written back; the new baseline."""
    old = baseline(path)
    new = {doc: min(cap, len(found.get(doc, []))) for doc, cap in sorted(old.items())}
    new = {d: c for d, c in new.items() if c}
    path.write_text(json.dumps(new, indent=1) + "\n")
    return new
