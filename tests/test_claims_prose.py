"""Numbers in the docs' prose (claims/prose.py, docs/claims.md "Numbers in prose"): every
measured-looking number outside the rendered tables is a claim reference or marked, or counted in a
per-doc baseline that may only go down."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from swarmhil.claims import prose
from swarmhil.claims.registry import registry


def texts(s: str) -> list[str]:
    return [h.text for h in prose.scan(s, "x.md")[0]]


def test_the_scan_finds_numbers_with_units_ratios_and_percentages():
    s = "it took 12.3 s, 2.1 m/s, 54 MB and 4.5x (or ×2.58, 3 times, 37 %, 3-4 min, 1 340 s, 2–7 ms, 10 m/s²)"
    assert texts(s) == ["12.3 s", "2.1 m/s", "54 MB", "4.5x", "×2.58", "3 times", "37 %", "3-4 min", "1 340 s",
                        "2–7 ms", "10 m/s²"]


def test_the_scan_leaves_names_counts_code_comments_tables_and_links_alone():
    s = ("sc07, paper 002, Fig. 10, 20 spacecraft, a 2x2 grid, 0x12, 3 x |v|, step 5 more, `12 s`, ``4 ms``, "
         "<!-- 9 s -->, [the page](docs/5 s.md), https://example.org/3m")
    assert texts(s) == []
    doc = ("before 1 s\n```sh\nsleep 2 s  # 3 h\n```\n<!-- claims:t -->\n| 4 m |\n<!-- /claims -->\n"
           "~~~\n5 km\n~~~\nafter 6 h\n<!-- kernel-drift table: rendered -->\n| 7 m |\n<!-- /kernel-drift table -->\n8 s\n")
    hits = prose.scan(doc, "x.md")[0]
    assert [(h.line, h.text) for h in hits] == [(1, "1 s"), (11, "6 h"), (15, "8 s")]
    # an indented code block is code; a list item's indented continuation is prose
    doc = "para 1 s\n\n    code 2 s\n    more 3 s\n\n- item 4 s\n\n    continued 5 s\ntext 6 s\n    lazy 7 s\n"
    assert [(h.line, h.text) for h in prose.scan(doc, "x.md")[0]] == [(1, "1 s"), (6, "4 s"), (8, "5 s"), (9, "6 s"),
                                                                     (10, "7 s")]


def test_a_mark_covers_its_number_or_the_numbers_before_it_and_a_mark_alone_covers_the_next_block():
    assert texts("after 20 h<!-- param --> the error is 3.2 m") == ["3.2 m"]
    assert texts("after 20 h the error is 3.2 m <!-- paper -->") == []
    assert texts("at 1 s steps to 300 s<!-- param -->") == ["1 s"]  # right after a number: that number only
    assert texts("at 1 s steps to 300 s <!-- param -->") == []
    assert texts("a 5 s lease<!-- def: Zenoh --> and 2 s <!-- param -->, then 7 s") == ["7 s"]
    assert texts("<!-- param -->\n| a | 10 s |\n| b | 20 s |\n\nafter 30 s") == ["30 s"]
    assert texts("<!-- no mark -->\n10 s") == ["10 s"]  # any other comment is not a mark
    assert texts("10 s <!-- parameter -->") == ["10 s"]  # nor a word that only begins like one


def test_a_claim_reference_covers_one_number_and_must_be_what_the_registry_renders(tmp_path: Path):
    reg = registry()
    c = reg.claims["p004.paper.e-max"]
    good, bad = c.render(), "9" + c.render()
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text(f"largest 1 s then {good} m<!-- claim:p004.paper.e-max --> after 200 s\n")
    (tmp_path / "docs" / "a.md").write_text(f"the error {bad} m<!-- claim:p004.paper.e-max -->\n"
                                            "and 3 m<!-- claim:no.such.claim -->\n"
                                            f"```\n{bad} m<!-- claim:p004.paper.e-max -->\n```\n")
    assert {d: [h.text for h in hs] for d, hs in prose.unmarked(tmp_path).items()} == {"README.md": ["1 s", "200 s"]}
    errors = prose.ref_errors(reg.claims, tmp_path)
    assert len(errors) == 2, errors
    assert errors[0].startswith(f"docs/a.md:1: {bad} is not the registry's p004.paper.e-max = {good}")
    assert errors[1].startswith("docs/a.md:2: <!-- claim:no.such.claim --> is not a claim")
    assert prose.write_refs(reg.claims, tmp_path) == ["docs/a.md"]
    fixed = (tmp_path / "docs" / "a.md").read_text()
    assert fixed.startswith(f"the error {good} m<!-- claim:p004.paper.e-max -->\n")
    assert f"```\n{bad} m" in fixed  # code is not prose: left as it was
    assert len(prose.ref_errors(reg.claims, tmp_path)) == 1


def test_the_baseline_fails_a_doc_that_gains_a_number_and_asks_to_lower_one_that_lost_some(tmp_path: Path):
    found = {"a.md": [prose.Hit("a.md", 3, "4 s"), prose.Hit("a.md", 9, "5 m")], "b.md": [prose.Hit("b.md", 1, "2 h")]}
    assert prose.baseline_errors(found, {"a.md": 2, "b.md": 1}) == []
    more = prose.baseline_errors(found, {"a.md": 1, "b.md": 1})
    assert more == ["a.md: 2 unmarked numbers in prose, 1 allowed: 3: 4 s; 9: 5 m"]
    assert prose.baseline_errors(found, {"a.md": 2})[0].startswith("b.md: 1 unmarked numbers in prose, 0 allowed")
    assert "lower it" in prose.baseline_errors(found, {"a.md": 3, "b.md": 1})[0]
    path = tmp_path / "baseline.json"
    path.write_text(json.dumps({"a.md": 5, "b.md": 0, "c.md": 4}))
    # lowered to what each doc holds now, never raised (b.md stays at 0 though it holds one), emptied entries dropped
    assert prose.lower_baseline(found, path) == {"a.md": 2}
    assert json.loads(path.read_text()) == {"a.md": 2}


def test_a_mark_on_a_heading_line_is_refused(tmp_path: Path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("<!-- param -->\n## Over 550 s\n\ntext\n")
    (tmp_path / "docs" / "a.md").write_text("# A\n\n### Case (i), 550 s <!-- param -->\n")
    assert prose.heading_marks(tmp_path) == ["docs/a.md:3: a mark on a heading line; put it on the line before"]
    assert prose.unmarked(tmp_path) == {}  # the mark before the heading covers it


def test_every_doc_is_within_its_baseline_and_every_claim_reference_is_the_registrys():
    found = prose.unmarked()
    errors = (prose.baseline_errors(found, prose.baseline()) + prose.ref_errors(registry().claims)
              + prose.heading_marks())
    assert errors == [], "\n".join(errors)


@pytest.mark.parametrize("doc", ["README.md", "docs/performance.md", "docs/architecture.md", "docs/claims.md"])
def test_the_docs_a_user_reads_first_have_no_unmarked_number(doc: str):
    assert doc not in prose.baseline(), f"{doc} is gone through: it has no baseline"
    assert [str(h) for h in prose.unmarked().get(doc, [])] == []


def test_swarmhil_claims_prose_lists_and_exits_by_the_baseline():
    from swarmhil.claims.cli import claims

    out = CliRunner().invoke(claims, ["--prose"])
    assert out.exit_code == 0, out.output
    listed = [line for line in out.stdout.splitlines() if not line.startswith("PROSE")]
    assert len(listed) == sum(prose.baseline().values())
    assert CliRunner().invoke(claims, ["--lower-baseline"]).exit_code == 2
