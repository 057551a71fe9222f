"""Import rules of the mission rooms (issue 25; docs/architecture.md "Mission rooms (issue 25)").

Read from the source with `ast` (every import statement, function-local ones included, relative
ones resolved; plus literal module names handed to `importlib.import_module` / `__import__`), so a
rule is checked whether or not a code path runs:

- no module under `plant/` imports `agent` (the plant never imports flight software), and from
  `missions` only rooms' contracts;
- no module under `agent/` imports `plant`, `dashboards` or `deploy`, and from `missions` only
  rooms' contracts;
- a room's `contract` imports nothing but the standard library, numpy and `bus`;
- the `__init__` of `missions` and of every room imports nothing.

And at run time, in a fresh interpreter: a contract loads no project module but `bus` and
`missions`, and no pydantic or scipy; the flight software of papers 000 and 004 loads no `plant`,
`dashboards` or `deploy` module.
"""
from __future__ import annotations

import ast
import json
import subprocess
import sys
import tomllib
from collections.abc import Iterator
from pathlib import Path

from conftest import ROOT

CONTRACT_MAY_IMPORT = {"numpy", "bus"}
ROOMS_WITH_CONTRACT = ("p000_capture", "p004_lbdnn")


def module_name(path: Path) -> list[str]:
    """Dotted name parts of a source file under ROOT (`pkg/__init__.py` -> [pkg])."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return parts[:-1] if parts[-1] == "__init__" else parts


def imported(path: Path) -> Iterator[tuple[int, str]]:
    """(line, absolute module name) of every import in a file. `from M import a` yields M and M.a
    (a may be a submodule); relative imports are resolved against the file's package."""
    mod = module_name(path)
    package = mod if path.name == "__init__.py" else mod[:-1]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, a.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            if name == "__future__":
                continue
            yield node.lineno, name
            for a in node.names:
                if a.name != "*":
                    yield node.lineno, f"{name}.{a.name}"
        elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)
              and (getattr(node.func, "attr", None) == "import_module" or getattr(node.func, "id", None)
                   in ("import_module", "__import__"))):
            yield node.lineno, node.args[0].value


def sources(top: str) -> list[Path]:
    files = sorted((ROOT / top).rglob("*.py"))
    assert files, f"no modules under {top}/"
    return files


def only_contracts(name: str) -> bool:
    """From `missions`, a module may import the packages and the rooms' contracts, nothing else."""
    parts = name.split(".")
    return parts[0] != "missions" or len(parts) <= 2 or parts[2] == "contract"


def violations(top: str, forbidden: set[str]) -> list[str]:
    bad = []
    for path in sources(top):
        for line, name in imported(path):
            if name.split(".")[0] in forbidden or not only_contracts(name):
                bad.append(f"{path.relative_to(ROOT)}:{line}: {name}")
    return bad


def test_the_plant_imports_no_flight_software() -> None:
    assert not violations("plant", {"agent"})
    # the rule is exercised: the sensing kinds of papers 000 and 004 read their contracts
    for kind, room in (("p000", "p000_capture"), ("p004", "p004_lbdnn")):
        names = {n for _, n in imported(ROOT / "plant" / "sensing" / f"{kind}.py")}
        assert f"missions.{room}.contract" in names, (kind, sorted(names))


def test_the_flight_software_imports_no_plant_report_or_launcher() -> None:
    assert not violations("agent", {"plant", "dashboards", "deploy"})


def test_contracts_import_only_bus_and_numpy() -> None:
    contracts = sorted((ROOT / "missions").glob("*/contract.py"))
    assert {p.parent.name for p in contracts} >= set(ROOMS_WITH_CONTRACT), contracts
    bad = [f"{p.relative_to(ROOT)}:{line}: {name}" for p in contracts for line, name in imported(p)
           if name.split(".")[0] not in CONTRACT_MAY_IMPORT | set(sys.stdlib_module_names)]
    assert not bad, bad


def test_room_packages_import_nothing() -> None:
    inits = [ROOT / "missions" / "__init__.py", *sorted((ROOT / "missions").glob("*/__init__.py"))]
    bad = [f"{p.relative_to(ROOT)}:{line}: {name}" for p in inits for line, name in imported(p)]
    assert not bad, bad


def loaded_after(imports: str) -> set[str]:
    """The modules a fresh interpreter holds after `imports` (run from ROOT)."""
    code = f"import json, sys\n{imports}\nprint(json.dumps(sorted(sys.modules)))"
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    return set(json.loads(p.stdout))


def test_contracts_are_light_and_fsw_loads_no_plant() -> None:
    project = {"agent", "plant", "link", "deploy", "dashboards", "swarmhil"}
    mods = loaded_after("\n".join(f"import missions.{r}.contract" for r in ROOMS_WITH_CONTRACT))
    tops = {m.split(".")[0] for m in mods}
    assert not tops & (project | {"pydantic", "scipy"}), sorted(tops & (project | {"pydantic", "scipy"}))
    assert {f"missions.{r}.contract" for r in ROOMS_WITH_CONTRACT} <= mods
    mods = loaded_after("import agent.missions.p000_capture, agent.missions.p004_lbdnn")
    tops = {m.split(".")[0] for m in mods}
    assert not tops & {"plant", "dashboards", "deploy", "pydantic"}, sorted(tops & {"plant", "dashboards", "deploy", "pydantic"})
    assert "agent.missions.p004_lbdnn.controller" in mods and "missions.p004_lbdnn.contract" in mods


def test_rooms_are_installed_and_in_the_image() -> None:
    """Every process reads a contract: the package list and the image carry `missions`."""
    include = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]["include"]
    assert "missions*" in include, include
    copies = [ln.split() for ln in (ROOT / "deploy" / "Dockerfile").read_text().splitlines() if ln.startswith("COPY ")]
    assert ["COPY", "missions", "missions"] in copies, copies
