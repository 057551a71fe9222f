"""The claims registry's types: a claim, the tolerance it is checked with, and the doc tables it fills.

A **claim** is one number (or one short list of identifiers) a doc states: the function that
computes it from a named **source** (a run or a computation, cached so that several claims share
one run), the value recorded here, the value under the other kernel set (docs/claims.md "Two
kernel sets") and the tolerance chosen from their spread. A **table** is the markdown table a doc
includes between `<!-- claims:ID -->` and `<!-- /claims -->`: each cell is a template whose numbers
are `{claim-id}` placeholders, and the verdict cell is computed from the values, never typed.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

Value = float | int | str | tuple[str, ...]
Values = Mapping[str, Value]
TIERS = ("quick", "all", "study", "bench")  # seconds, minutes (system tests), hours (not CI), timings


@dataclass(frozen=True)
class Tol:
    """How far a rerun may land from the recorded value: |measured - recorded| <= abs + rel*|recorded|,
    or, when the registry resolved an envelope from a measured ensemble (`lo`, `hi`), lo <= measured <= hi.

    Strings and identifier lists must match exactly. `shape_only` (bench timings on the shared
    machine): only that a finite number of the right kind was measured."""

    abs: float = 0.0
    rel: float = 0.0
    shape_only: bool = False
    auto: bool = False  # resolved by the registry from the measured spread (`resolve_tol`)
    lo: float | None = None  # the band's edges when resolved as an envelope (both set or neither)
    hi: float | None = None

    def band(self, recorded: float) -> tuple[float, float]:
        """The interval of numbers that stand for `recorded`."""
        if self.lo is not None and self.hi is not None:
            return self.lo, self.hi
        half = self.abs + self.rel * abs(float(recorded))
        return float(recorded) - half, float(recorded) + half

    def holds(self, measured: Value, recorded: Value) -> bool:
        """Whether `measured` stands for `recorded` (never when nothing was recorded)."""
        if recorded is None:
            return False
        if isinstance(recorded, (str, tuple)):
            return measured == recorded
        if not isinstance(measured, (int, float)) or isinstance(measured, bool) or not math.isfinite(measured):
            return False
        if self.shape_only:
            return True
        lo, hi = self.band(float(recorded))
        return lo - 1e-12 <= float(measured) <= hi + 1e-12

    def describe(self) -> str:
        if self.shape_only:
            return "presence and shape only"
        if self.auto:
            return "auto (not resolved)"
        if self.lo is not None and self.hi is not None:
            return f"within [{self.lo:.4g}, {self.hi:.4g}]"
        parts = ([f"±{self.abs:g}"] if self.abs else []) + ([f"±{100 * self.rel:g} %"] if self.rel else [])
        return " + ".join(parts) or "exact"


@dataclass(frozen=True)
class Source:
    """A named computation whose result (a flat dict of JSON values) several claims share.

    `run(get)` is pure in its inputs (scenario, options); `get(name)` gives another source's result
    (a derived source, e.g. a sweep made of runs). The runner caches results per kernel set."""

    name: str
    tier: str
    run: Callable[[Callable[[str], dict[str, Any]]], dict[str, Any]]
    what: str  # the command that regenerates it, for the docs and the runner's report
    # The test that makes this very run in CI and checks its claims from it (`claims.check`), so
    # CI's `swarmhil claims --all --untested` need not make it twice; `from_run` turns the run
    # object that test holds into this source's result (`run` = from_run(the run)).
    checked_by: str = ""
    from_run: Callable[[Any], dict[str, Any]] | None = None
    uses: tuple[str, ...] = ()  # the sources a derived source reads through `get` (none: a run of its own)
    # The same run with its initial state moved by one ulp in the k-th way (k = 1, 2, ...): for a
    # closed loop that amplifies last bits, its claims' tolerances cover the spread of these runs
    # too (`swarmhil claims --record --nudges N`, docs/claims.md "One-ulp nudges").
    nudged: Callable[[int], Callable[[Callable[[str], dict[str, Any]]], dict[str, Any]]] | None = None

    def __post_init__(self) -> None:
        if self.tier not in TIERS:
            raise ValueError(f"source {self.name}: tier {self.tier!r} not in {TIERS}")
        if bool(self.checked_by) != (self.from_run is not None):
            raise ValueError(f"source {self.name}: checked_by and from_run go together")


@dataclass(frozen=True)
class Claim:
    """One number a doc states, with what regenerates it and how closely.

    value: recorded on the reference machine (AMD EPYC, AVX2) with its default kernels; alt: the
    same under `OPENBLAS_CORETYPE=Sandybridge NPY_DISABLE_CPU_FEATURES=X86_V3` (None: not measured,
    e.g. bench timings); tol chosen from |value - alt| with a margin (docs/claims.md)."""

    id: str
    source: str
    compute: Callable[[Mapping[str, Any]], Value]
    tol: Tol
    what: str  # what the number is, in words
    fmt: str = ".3g"  # format spec of the value in the doc (str.format mini-language)
    value: Value | None = None  # filled from claims/recorded.json by the registry
    alt: Value | None = None
    nudged: tuple[float, ...] = ()  # the values of the source's one-ulp nudged runs (recorded.json)
    machines: tuple[float, ...] = ()  # the default kernels' values on other processors (recorded.json)
    # A difference meant to be about zero (round-off around a plane, a floor against the truth): its
    # band may reach zero. Any other claim with a non-zero value must have a band that stops short of
    # zero, so that it can fail (`band_reaches_zero`, refused by the registry).
    residual: bool = False

    def render(self, v: Value | None = None, spec: str | None = None) -> str:
        """The value as the doc prints it."""
        v = self.value if v is None else v
        if v is None:
            return "(not recorded)"
        if isinstance(v, tuple):
            return ", ".join(v) if v else "none"
        if isinstance(v, str):
            return v
        return number(v, spec or self.fmt)


def number(v: float | int, spec: str) -> str:
    """A number as the docs print it: str.format's spec, thousands with a space (`,` in the spec),
    exponents short (1.4e9, not 1.4e+09); `s3` = three significant digits with thousands spaced."""
    if isinstance(v, float) and math.isinf(v):
        return "inf" if v > 0 else "-inf"
    if spec == "s3":
        v = float(f"{v:.3g}")
        spec = ",.0f" if abs(v) >= 1000 else ".3g"
    out = format(v, spec).replace(",", " ")
    return re.sub(r"e([+-])0*(\d)", lambda m: "e" + ("-" if m.group(1) == "-" else "") + m.group(2), out)


def half_digit(value: float, spec: str) -> float:
    """Half a unit of the last digit `spec` prints of `value`: the smallest change the doc shows."""
    v = abs(float(value))
    if spec == "s3":
        spec = ".3g"
    m = re.search(r"\.(\d+)([fge])", spec)
    if m is None:
        return 0.5  # integers ('d', ',.0f' without decimals)
    n, kind = int(m.group(1)), m.group(2)
    if kind == "f":
        return 0.5 * 10.0 ** -n
    if v == 0.0 or not math.isfinite(v):
        return 0.0
    return 0.5 * 10.0 ** (math.floor(math.log10(v)) - max(n, 1) + 1)


ENVELOPE_PAD = 0.5  # with an ensemble: the band is [min, max] of the sample widened by this x its range each side
CAP = 0.9  # a non-residual band stops at (1 - CAP) x the value: it never reaches zero (docs/claims.md "The cap")


def resolve_tol(tol: Tol, value: Value | None, alt: Value | None, spec: str, margin: float = 3.0,
                nudged: Sequence[float] = (), machines: Sequence[float] = (), residual: bool = False) -> Tol:
    """An `auto` tolerance made concrete from the measured spread, so the measured last-bit spread
    passes and any change the doc would show beyond it fails.

    Two samples (value, alt): value ± max(margin x |value - alt|, half a unit of the doc's last
    printed digit, tol.abs) + tol.rel x |value|. An ensemble (the one-ulp nudged runs, other
    processors' values): the envelope [min - p, max + p] of {value, alt, nudged, machines}, with
    p = max(ENVELOPE_PAD x its range, half a digit, tol.abs + tol.rel x |value|). Either way, unless
    the claim is a residual, the edge towards zero is capped at (1 - CAP) x value: a band never
    reaches zero for a non-zero value (a recorded sample beyond the cap then fails the tests)."""
    if not tol.auto or not isinstance(value, (int, float)):
        return tol
    v = float(value)
    digit = half_digit(v, spec)
    spread = abs(v - float(alt)) if isinstance(alt, (int, float)) and math.isfinite(float(alt)) else 0.0
    sample = [v] + [float(x) for x in ([alt] if isinstance(alt, (int, float)) else []) + list(nudged) + list(machines)
                    if math.isfinite(float(x))]
    if nudged or machines:
        pad = max(ENVELOPE_PAD * (max(sample) - min(sample)), digit, tol.abs + tol.rel * abs(v))
        out = Tol(lo=min(sample) - pad, hi=max(sample) + pad)
    else:
        out = Tol(abs=max(tol.abs, margin * spread, digit), rel=tol.rel)
    lo, hi = out.band(v)
    if residual or v == 0.0 or (lo > 0.0 if v > 0 else hi < 0.0):
        return out
    return Tol(lo=(1.0 - CAP) * v, hi=hi) if v > 0 else Tol(lo=lo, hi=(1.0 - CAP) * v)


def band_reaches_zero(claim: Claim) -> bool:
    """Whether a numeric, non-zero, non-residual claim's band includes zero (or crosses it): a
    check that a measured 0 would pass cannot fail where it matters. Timings (`shape_only`) aside."""
    v = claim.value
    if claim.residual or claim.tol.shape_only or not isinstance(v, (int, float)) or isinstance(v, bool) or v == 0:
        return False
    lo, hi = claim.tol.band(float(v))
    return lo <= 0.0 if v > 0 else hi >= 0.0


PLACEHOLDER = re.compile(r"\{([a-z0-9][a-z0-9_.\-]*)(?::([^{}]*))?\}")
NUMBER = re.compile(r"(?<![A-Za-z0-9_.])\d+(?:[.,]\d+)*")


@dataclass(frozen=True)
class Row:
    """One table row: a template per column. Numbers in the measured columns come from
    `{claim-id}` or `{claim-id:spec}` placeholders only, except those listed in `params` (thresholds
    and times that define what is measured, e.g. the '5' of 'below 5 m'); `verdict` computes the
    verdict cell from the claims' values."""

    cells: tuple[str, ...]
    verdict: Callable[[Values], str] | None = None
    params: tuple[str, ...] = ()


@dataclass(frozen=True)
class Table:
    """A doc table regenerated from the registry: doc path, marker id, header, rows.

    `measured`: the indices of the columns whose numbers must all be claims (the paper's own figure
    and the claim's wording are not measured)."""

    id: str
    doc: str
    header: tuple[str, ...]
    rows: tuple[Row, ...]
    measured: tuple[int, ...]
    verdict_col: int | None = None
    align: tuple[str, ...] = field(default=())

    def placeholders(self) -> list[str]:
        """The claim ids this table uses, in order of appearance."""
        out: list[str] = []
        for row in self.rows:
            for cell in row.cells:
                out += [m.group(1) for m in PLACEHOLDER.finditer(cell) if m.group(1) not in out]
        return out


def literal_numbers(template: str) -> list[str]:
    """The numbers written in a template outside its placeholders (sc07, Fig. 10 and x^2 excepted:
    a number glued to a letter or following 'Fig. ' is a name)."""
    text = PLACEHOLDER.sub(" ", template)
    text = re.sub(r"Figs?\.\s*\d+(?:\s*[-–,]\s*\d+)*", " ", text)
    text = re.sub(r"\^\d+", " ", text)
    return [m.group(0) for m in NUMBER.finditer(text)]


def check_row_numbers(row: Row, measured: Sequence[int]) -> list[str]:
    """Literal numbers in the measured columns that are not declared parameters."""
    bad: list[str] = []
    for i in measured:
        if i < len(row.cells):
            bad += [n for n in literal_numbers(row.cells[i]) if n not in row.params]
    return bad
