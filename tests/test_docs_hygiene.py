"""The docs are written for today's reader (docs/*.md and README.md): no paths of the machine they
were written on, no issue-tracker numbers, no branch names. History lives in git."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from conftest import ROOT

DOCS = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]

RULES: dict[str, re.Pattern[str]] = {
    # an absolute path of a machine (a home, a work tree, a checkout's own virtualenv), or a `cd` into
    # a worktree folder; relative paths (.venv/bin/python, runs/...) and /tmp, /dev/shm are fine
    "machine path": re.compile(r"(?<![\w.~-])/(?:work|home|root|Users|mnt)/[\w.-]+|/[\w./-]*/\.venv\b|\bcd \S*\bwt[-/]"),
    # an issue-tracker reference: "issue 36", "issues 16 and 29", "(#12)", "#12"
    "issue number": re.compile(r"(?i)\bissues?\s+#?\d+|(?<![\w&/])#\d+\b"),
    # a branch: "this branch", "on branch p003b", "(branch fastekf)", "main vs this branch"
    "branch name": re.compile(r"(?i)\bthis branch\b|\bbranch(?:es)?\s+[`'\"]?[a-z][\w.-]*\d[\w.-]*|\(branch \w+|\bon branch\b"
                              r"|\bbranch (?:fastbatch|batch2|mpfast|fastekf|cambatch|main)\b"),
}


def violations(text: str) -> list[tuple[int, str, str]]:
    """(line, rule, the matched text) for each rule broken in a doc's text."""
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        for rule, pat in RULES.items():
            out += [(n, rule, m.group(0)) for m in pat.finditer(line)]
    return out


def test_the_rules_catch_what_they_are_for():
    """Positive and negative controls of each pattern."""
    bad = ["cd /work/wt/p004 && make", "run /work/main/.venv/bin/python", "`/srv/x/.venv/bin/pip`",
           "added in issue 36", "(issue 4, paper 002)", "Issues 16 and 29", "see #12", "measured on this branch",
           "on branch p003b", "(branch fastekf)", "main vs this branch", "cd wt-trustdocs"]
    assert [s for s in bad if not violations(s)] == []
    good = [".venv/bin/python -m pytest", "runs/sweep-noise", "/tmp/p003", "/dev/shm/x.zenoh", "the issue's list",
            "paper 002 section 5", "[link](#one-installed-name)", "&#12;", "branching factor", "x/home/y",
            "the tracker's issues", "`git log` keeps the history"]
    assert [s for s in good if violations(s)] == []


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_docs_have_no_machine_paths_issue_numbers_or_branch_names(doc: Path):
    found = violations(doc.read_text())
    assert not found, "\n".join(f"{doc.relative_to(ROOT)}:{n}: {rule}: {m!r}" for n, rule, m in found)


def test_readme_layout_names_every_top_level_folder():
    """README's layout table has a row for every folder the repository tracks at its top."""
    import subprocess

    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    folders = {p.split("/")[0] for p in tracked if "/" in p}
    layout = (ROOT / "README.md").read_text().split("## Layout", 1)[1].split("\n## ", 1)[0]
    rows = set(re.findall(r"^\| `([^`/]+)/` \|", layout, re.M))
    assert folders - rows == set(), f"README's layout lacks {sorted(folders - rows)}"
    assert rows - folders == set(), f"README's layout names folders that do not exist: {sorted(rows - folders)}"
