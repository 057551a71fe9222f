"""Import rules of the mission rooms (issue 25; docs/architecture.md "Mission rooms (issue 25)").

Read from the source with `ast` (every import statement, function-local ones included, relative
ones resolved; plus literal module names handed to `importlib.import_module` / `__import__`), so a
rule is checked whether or not a code path runs:

- no module under `plant/` imports `agent` (the plant never imports flight software), and from
  `missions` only rooms' contracts; nor does any room's `sense` (nor `dashboards`, `deploy`);
- no module under `agent/` or in a room's `fsw/` imports `plant`, `dashboards` or `deploy`, and from
  `missions` only rooms' contracts (an `fsw` also its own modules);
- a room's `report` imports no `agent`, `deploy`, sensing kind, or room part but contracts and itself;
- each of papers 000, 001, 003, 004 lives in its room: no product module outside `missions/` is
  named after it (paper 002's room is a later step);
- a room's `contract` imports nothing but the standard library, numpy and `bus`;
- the `__init__` of `missions` and of every room imports nothing.

And over the import graph of the product modules (every package the wheel installs):

- no import circle (module-level imports, the ones Python runs on import; and none either when the
  function-local ones are counted);
- no arrow from a lower layer to a higher one: `bus` <- `plant` / `agent` / `link` <- `dashboards`
  (with `swarmhil`, the analysis API) <- `deploy`; a room's contract sits on `bus`;
- every function-local import of a project module says why it is not at the top (a comment on
  its line: an optional extra, the agent image's size, a process role's start-up), and their number
  does not grow (LOCAL_IMPORTS_MAX).

And at run time, in a fresh interpreter: a contract loads no project module but `bus` and
`missions`, and no pydantic or scipy; the flight software of papers 000 and 004 loads no `plant`,
`dashboards` or `deploy` module; each process loads its own part of the rooms through
bus/discovery.py `import_role` (the agent's catalogue only `fsw`, the plant's sensing registry only
`sense`, the reporter's sections only `report`, with the contracts); the viewer gets a room's
landmark kind through the hook its report registers.
"""
from __future__ import annotations

import ast
import functools
import json
import subprocess
import sys
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

from conftest import ROOT

CONTRACT_MAY_IMPORT = {"numpy", "bus"}
PRODUCT = ("agent", "bus", "plant", "link", "dashboards", "deploy", "missions", "swarmhil")
LAYERS = {"bus": 0, "plant": 1, "agent": 1, "link": 1, "dashboards": 2, "swarmhil": 2, "deploy": 3}
ROOM_PART_LAYER = {"contract": 0, "fsw": 1, "sense": 1, "report": 2, "seeds": 3}  # docs/architecture.md
LOCAL_IMPORTS_MAX = 158  # +2 `swarmhil compose --hosts`: the proc router role takes the mesh options from deploy/router.py on use, deploy/compose.py the run security on use; +1 deploy/cli_scale.py (`swarmhil scale` loads the scenario schema on use); +1 deploy/campaign.py run_campaign: a fault campaign with --baseline judges the same windows on the baseline runs (dashboards/sections/faults.py with_baseline_outcomes, on use); +1 deploy/scenario.py _check_fault_starts (FaultWindow, on use as parse_faults); +4 issue 36: the batch mode loads the camera stack only for scene sensing (agent/batch.py, 3) and the plant its batch scenes (1); +1 swarmhil/__init__.py's lazy analysis API (PEP 562: the namespace root loads nothing); function-local imports of project modules: 142 after issue 25 step 3 (main at ba2b475: 240), +10 with the external flight software and faults, +1 fault campaigns (deploy commands loading what they run), +1 deploy/scenario.plant_config (the plant's config, where the scenario lives; an agent image loads deploy/scenario.py, not plant/), -1 deploy/campaign_compare (the rule and the count from plant/sensors.py), -5 issue 25 step 1 (the p000 and p003 reports read their contracts at the top)
ROOMS_WITH_CONTRACT = ("p000_capture", "p001_lattice", "p002_sabatini", "p003_surround", "p004_lbdnn")
ROOMS_MOVED = ("p000_capture", "p001_lattice", "p002_sabatini", "p003_surround", "p004_lbdnn")  # rooms whose fsw, sense and report live in missions/<room>/ (issue 25 steps 1-2)
NO_SENSE = {"p001_lattice", "p002_sabatini"}  # they fly the plant's generic kinds (`relative`; `rel` and the camera scene)
ROOMS_MOVED_TAGS = ("p000", "p001", "p002", "p003", "p004", "sabatini")  # no module outside missions/ is named after these papers


NAMESPACE = "swarmhil"
FOLDERS = (*PRODUCT, "claims")  # the repository's folders installed under the namespace
"""The one installed top-level name (issue 25): `swarmhil.agent` is the repository's agent/ folder."""


def short(name: str) -> str:
    """A module name without the installed namespace (`swarmhil.agent.node` -> `agent.node`): the
    rules below speak of the repository's folders."""
    head, _, rest = name.partition(".")
    return rest if head == NAMESPACE and rest.split(".")[0] in FOLDERS else name


def module_name(path: Path) -> list[str]:
    """Dotted name parts of a source file under ROOT (`pkg/__init__.py` -> [pkg])."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return parts[:-1] if parts[-1] == "__init__" else parts


def imported(path: Path) -> Iterator[tuple[int, str]]:
    """(line, absolute module name without the namespace: `short`) of every import in a file."""
    for line, name in imported_as_written(path):
        yield line, short(name)


@functools.cache
def parsed(path: Path) -> ast.Module:
    """A source file's syntax tree, parsed once per session (the tests here only read the trees)."""
    return ast.parse(path.read_text(), str(path))


def imported_as_written(path: Path) -> Iterator[tuple[int, str]]:
    """(line, absolute module name) of every import in a file. `from M import a` yields M and M.a
    (a may be a submodule); relative imports are resolved against the file's package."""
    mod = module_name(path)
    package = mod if path.name == "__init__.py" else mod[:-1]
    for node in ast.walk(parsed(path)):
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
    """The modules under ROOT/top, not through swarmhil/'s links (each file once, by its folder's name)."""
    real = ROOT.resolve()
    files = sorted(p for p in (ROOT / top).rglob("*.py") if p.resolve() == real / p.relative_to(ROOT))
    assert files, f"no modules under {top}/"
    return files


def only_contracts(name: str, own: str = "") -> bool:
    """From `missions`, a module may import the packages and the rooms' contracts, nothing else
    (and, with `own` = "missions.<room>.<part>", its own part: an fsw its fsw modules)."""
    parts = name.split(".")
    return (parts[0] != "missions" or len(parts) <= 2 or parts[2] == "contract"
            or bool(own) and (name == own or name.startswith(own + ".")))


def violations(top: str, forbidden: set[str], files: list[Path] | None = None) -> list[str]:
    """Imports of `forbidden` top-level packages, or of a room's part other than a contract (or
    the importer's own part), in the modules under `top` (or in `files`)."""
    bad = []
    for path in sources(top) if files is None else files:
        mod = module_name(path)
        own = ".".join(mod[:3]) if mod[0] == "missions" and len(mod) > 2 else ""
        for line, name in imported(path):
            if name.split(".")[0] in forbidden or not only_contracts(name, own):
                bad.append(f"{path.relative_to(ROOT)}:{line}: {name}")
    return bad


def room_parts(role: str) -> list[Path]:
    """Every module of the part `role` of every room: missions/<room>/<role>.py or <role>/**."""
    return sorted([*(ROOT / "missions").glob(f"*/{role}.py"), *(ROOT / "missions").glob(f"*/{role}/**/*.py")])


def test_the_plant_imports_no_flight_software() -> None:
    assert not violations("plant", {"agent"})
    assert not violations("missions", {"agent", "dashboards", "deploy"}, room_parts("sense"))
    # the rule is exercised: the sensing kinds of papers 000, 003 and 004 read their contracts
    for room in set(ROOMS_MOVED) - NO_SENSE:
        names = {n for _, n in imported(ROOT / "missions" / room / "sense.py")}
        assert f"missions.{room}.contract" in names and "plant.sensing.registry" in names, (room, sorted(names))


def test_the_flight_software_imports_no_plant_report_or_launcher() -> None:
    assert not violations("agent", {"plant", "dashboards", "deploy"})
    fsw = room_parts("fsw")
    assert {p.relative_to(ROOT / "missions").parts[0] for p in fsw} >= set(ROOMS_MOVED), fsw
    assert not violations("missions", {"plant", "dashboards", "deploy"}, fsw)
    # and the rule is exercised: an fsw may import its own modules, not another room's nor a sense
    assert only_contracts("missions.p003_surround.fsw.nash", "missions.p003_surround.fsw")
    assert not only_contracts("missions.p003_surround.sense", "missions.p003_surround.fsw")
    assert not only_contracts("missions.p004_lbdnn.fsw", "missions.p003_surround.fsw")


def test_a_report_imports_no_flight_software_nor_sensing() -> None:
    reports = room_parts("report")
    assert {p.relative_to(ROOT / "missions").parts[0] for p in reports} >= set(ROOMS_MOVED), reports
    assert not violations("missions", {"agent", "deploy"}, reports)
    assert not [f"{p}: {n}" for p in reports for _, n in imported(p) if n.startswith("plant.sensing")]


def test_each_mission_lives_in_its_room() -> None:
    """No product module outside missions/ is named after a paper, and each room has its contract,
    fsw, report and (but papers 001 and 002) sense."""
    mods = product_modules()
    bad = [m for m in mods if not m.startswith("missions.") and any(t in m for t in ROOMS_MOVED_TAGS)]
    assert not bad, bad
    for room in ROOMS_MOVED:
        for part in ("contract", "fsw", "report") + (("sense",) if room not in NO_SENSE else ()):
            assert f"missions.{room}.{part}" in mods, (room, part)
    assert "missions.p000_capture.seeds" in mods and "missions.p000_capture.report.sweep" in mods


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
    mods = set(json.loads(p.stdout))
    assert not {m.split(".")[0] for m in mods} & set(PRODUCT) - {NAMESPACE}, "a module loaded outside the namespace"
    return {short(m) for m in mods} - {NAMESPACE}  # the namespace's own __init__ loads nothing (PEP 562)


def test_contracts_are_light_and_fsw_loads_no_plant() -> None:
    project = {"agent", "plant", "link", "deploy", "dashboards", "swarmhil"}
    mods = loaded_after("\n".join(f"import swarmhil.missions.{r}.contract" for r in ROOMS_WITH_CONTRACT))
    tops = {m.split(".")[0] for m in mods}
    assert not tops & (project | {"pydantic", "scipy"}), sorted(tops & (project | {"pydantic", "scipy"}))
    assert {f"missions.{r}.contract" for r in ROOMS_WITH_CONTRACT} <= mods
    mods = loaded_after("import swarmhil.missions.p000_capture.fsw, swarmhil.missions.p004_lbdnn.fsw, "
                        "swarmhil.missions.p002_sabatini.fsw")
    tops = {m.split(".")[0] for m in mods}
    assert not tops & {"plant", "dashboards", "deploy", "pydantic"}, sorted(tops & {"plant", "dashboards", "deploy", "pydantic"})
    assert "missions.p004_lbdnn.fsw.controller" in mods and "missions.p004_lbdnn.contract" in mods
    assert "missions.p002_sabatini.fsw.sabatini" in mods and "scipy" not in tops  # the DRE solve loads scipy on use


def parts_loaded(mods: set[str]) -> set[str]:
    """The roles of the rooms' parts among loaded modules ({"fsw", "sense", ...})."""
    return {m.split(".")[2] for m in mods if m.startswith("missions.") and m.count(".") >= 2}


def test_each_process_loads_its_own_part_of_the_rooms() -> None:
    """In a fresh interpreter: the agent's catalogue (every controller) loads every room's fsw and
    no sense, report, plant, dashboards or deploy module; the plant's sensing registry loads the
    senses and no fsw or report; the reporter's sections load the reports and no fsw or sense."""
    mods = loaded_after("from swarmhil.agent.catalogue import known_controllers; known_controllers()")
    assert parts_loaded(mods) == {"contract", "fsw"}, parts_loaded(mods)
    assert not {m.split(".")[0] for m in mods} & {"plant", "dashboards", "deploy"}
    assert {f"missions.{r}.fsw" for r in ROOMS_MOVED} <= mods
    mods = loaded_after("from swarmhil.plant.sensing import known_sensing; known_sensing()")
    assert parts_loaded(mods) == {"contract", "sense"}, parts_loaded(mods)
    assert not {m.split(".")[0] for m in mods} & {"agent", "dashboards", "deploy"}
    assert {f"missions.{r}.sense" for r in ROOMS_MOVED if r not in NO_SENSE} <= mods
    mods = loaded_after("from swarmhil.dashboards.sections import sections_for; sections_for({})")
    assert parts_loaded(mods) == {"contract", "report"}, parts_loaded(mods)
    assert "deploy" not in {m.split(".")[0] for m in mods}
    assert {f"missions.{r}.report" for r in ROOMS_MOVED} <= mods


def test_rooms_are_installed_and_in_the_image() -> None:
    """Every process reads a contract: the package list and the image carry `missions`."""
    include = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]["include"]
    assert include == ["swarmhil", "swarmhil.*"], include
    assert (ROOT / NAMESPACE / "missions").resolve() == (ROOT / "missions").resolve()
    copies = [ln.split() for ln in (ROOT / "deploy" / "Dockerfile").read_text().splitlines() if ln.startswith("COPY ")]
    assert ["COPY", "missions", "missions"] in copies and ["COPY", NAMESPACE, NAMESPACE] in copies, copies


# --- the import graph of the product modules ------------------------------------------------------------
def product_modules() -> dict[str, Path]:
    """{dotted name: source file} of every module the wheel installs."""
    return {".".join(module_name(p)): p for top in PRODUCT for p in sources(top)}


def resolve(name: str, mods: dict[str, Path] | set[str]) -> str | None:
    """The product module an imported name lands in (`pkg.mod.attr` -> `pkg.mod`), None if outside."""
    while name and name not in mods:
        name = name.rpartition(".")[0]
    return name or None


def import_statements(path: Path) -> Iterator[tuple[ast.Import | ast.ImportFrom, bool, bool]]:
    """(statement, function-local, under `if TYPE_CHECKING`) of every import statement of a file."""
    def visit(node: ast.AST, local: bool, typing_only: bool) -> Iterator[tuple[ast.Import | ast.ImportFrom, bool, bool]]:
        for ch in ast.iter_child_nodes(node):
            loc = local or isinstance(ch, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            tc = typing_only or (isinstance(ch, ast.If) and "TYPE_CHECKING" in ast.unparse(ch.test))
            if isinstance(ch, (ast.Import, ast.ImportFrom)):
                yield ch, loc, tc
            yield from visit(ch, loc, tc)

    yield from visit(parsed(path), False, False)


def targets(path: Path, stmt: ast.Import | ast.ImportFrom, mods: dict[str, Path]) -> set[str]:
    """The product modules a statement imports (`from M import a`: M.a when a is a module, else M),
    leaving out the importer's own packages (Python runs them before the importer, not because of it)."""
    mod = module_name(path)
    package = mod if path.name == "__init__.py" else mod[:-1]
    if isinstance(stmt, ast.Import):
        names = [short(a.name) for a in stmt.names]
    else:
        base = ".".join(package[:len(package) - stmt.level + 1] + ([stmt.module] if stmt.module else [])) \
            if stmt.level else short(stmt.module or "")
        names = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in stmt.names]
    own = {".".join(mod[:i]) for i in range(1, len(mod) + 1)}
    return {r for n in names if (r := resolve(n, mods)) is not None} - own


def graph(function_local: bool) -> dict[str, set[str]]:
    """module -> the product modules it imports when loaded (with `function_local`, also the
    imports inside functions); imports under `if TYPE_CHECKING` never run and are left out."""
    mods = product_modules()
    g: dict[str, set[str]] = {m: set() for m in mods}
    for m, path in mods.items():
        for stmt, local, typing_only in import_statements(path):
            if not typing_only and (function_local or not local):
                g[m] |= targets(path, stmt, mods)
    return g


def circles(g: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(g[v]):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            connect(v)
    return out


def layer(module: str) -> int:
    """The layer of a product module (docs/architecture.md "Mission rooms"): a room's part by its role."""
    parts = module.split(".")
    if parts[0] == "missions":
        return ROOM_PART_LAYER[parts[2]] if len(parts) > 2 else 0
    return LAYERS[parts[0]]


def test_no_import_circles() -> None:
    assert not circles(graph(function_local=False)), circles(graph(function_local=False))
    assert not circles(graph(function_local=True)), circles(graph(function_local=True))


def test_circles_are_found() -> None:
    """The finder sees a circle, through a package's `__init__` too, and nothing in a chain."""
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    mods = {"p": Path("p/__init__.py"), "p.m": Path("p/m.py")}
    assert resolve("p.m.f", mods) == "p.m" and resolve("p.x", mods) == "p" and resolve("q", mods) is None


def test_no_arrow_from_a_lower_layer_to_a_higher_one() -> None:
    mods = product_modules()
    bad = []
    for m, path in mods.items():
        for stmt, _local, _tc in import_statements(path):
            for t in targets(path, stmt, mods):
                if layer(t) > layer(m):
                    bad.append(f"{path.relative_to(ROOT)}:{stmt.lineno}: {m} (layer {layer(m)}) -> {t} (layer {layer(t)})")
    assert not bad, bad
    # the layers are exercised: every product top-level folder has a layer, and the dashboards read the plant
    assert {m.split(".")[0] for m in mods} <= set(LAYERS) | {"missions"}
    assert layer("dashboards.metrics") > layer("plant.sensors") and "plant.sensors" in graph(False)["dashboards.metrics"]


def _reason(path: Path, stmt: ast.Import | ast.ImportFrom) -> str:
    """The comment written on the lines of an import statement, without linter directives."""
    lines = path.read_text().splitlines()[stmt.lineno - 1:stmt.end_lineno]
    text = " ".join(ln.split("#", 1)[1] for ln in lines if "#" in ln)
    for directive in ("noqa", "type: ignore", "pragma"):
        text = text.split(directive)[0] if text.strip().startswith(directive) else text
    return text.strip(" :")


def local_project_imports() -> list[tuple[Path, ast.Import | ast.ImportFrom]]:
    mods = product_modules()
    return [(path, stmt) for path in mods.values() for stmt, local, _tc in import_statements(path)
            if local and targets(path, stmt, mods)]


def test_function_local_imports_of_the_project_say_why() -> None:
    found = local_project_imports()
    silent = [f"{p.relative_to(ROOT)}:{s.lineno}" for p, s in found if not _reason(p, s)]
    assert not silent, f"{len(silent)} function-local imports of project modules without a reason comment: {silent}"
    assert len(found) <= LOCAL_IMPORTS_MAX, f"{len(found)} function-local imports of project modules (max {LOCAL_IMPORTS_MAX})"


def test_lint_is_clean_and_ci_runs_it(tmp_path: Path) -> None:
    """`make lint` (ruff with pyproject.toml's rules, then mypy on the interfaces listed in its
    [tool.mypy]) passes on the tree, and .ci/run has it as a stage."""
    p = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "."], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-1000:]
    p = subprocess.run([sys.executable, "-m", "mypy", "--cache-dir", str(tmp_path / "mypy")], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and "Success" in p.stdout, p.stdout[-3000:] + p.stderr[-1000:]
    assert 'stage "lint" make lint' in (ROOT / ".ci" / "run").read_text()
    assert "\nlint: setup\n\t$(VENV)/bin/ruff check .\n\t$(VENV)/bin/mypy\n" in (ROOT / "Makefile").read_text()


def test_type_check_covers_the_interfaces() -> None:
    """The type check's file list names the interfaces issue 25 asks for (the bus, the flight-software
    and sensing interfaces, the typed configs, every room's contract), and each entry matches a file."""
    files = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["mypy"]["files"]
    files = [f.removeprefix(f"{NAMESPACE}/") for f in files]
    for must in ("bus/", "agent/controller.py", "plant/config.py", "plant/flight.py", "plant/sensing/registry.py",
                 "deploy/agent_image.py", "missions/*/contract.py"):
        assert must in files, must
    for entry in files:
        assert list(ROOT.glob(entry.rstrip("/"))), f"{entry} matches nothing"
    assert len(list(ROOT.glob("missions/*/contract.py"))) >= 2


JOB_ORDER = {"dashboards/navreport": ("read", "analysis", "diagnosis", "figures", "page"),
             "dashboards/bandwidth": ("read", "accounting", "figures", "page"),
             "missions/p000_capture/report": ("read", "analysis", "figures", "page"),
             # paper 002's analysis is its metrics hook; no `read`: its section reads only the reporter's truth
             "missions/p002_sabatini/report": ("metrics", "figures", "page"),
             "missions/p004_lbdnn/report": ("read", "analysis", "figures", "page")}
# a room's report: its page registers the section on discovery (paper 002's metrics registers its hook)
INIT_IMPORTS = {"missions/p000_capture/report": {"page"},
                "missions/p002_sabatini/report": {"metrics", "page"},
                "missions/p004_lbdnn/report": {"page"}}
# A tool beside the jobs, run on its own (`python -m`): it may import the jobs up to the one named, and
# no job imports it (paper 000's sweep tables read and analyse many runs; they draw nothing).
TOOLS = {"missions/p000_capture/report": {"sweep": "analysis"}}


@pytest.mark.parametrize("package", sorted(JOB_ORDER))
def test_report_modules_import_only_the_jobs_before_them(package: str) -> None:
    """A report package split by job (docs/architecture.md): `read` <- analysis <- `figures` <- `page`;
    each module imports only the ones before it, and the package's __init__ imports nothing (a
    room's report: its INIT_IMPORTS, `page`, which registers the section when the reporter discovers
    it, and paper 002's `metrics`, its metrics hook). Every module of the package is a job, the
    __init__ or one of its TOOLS."""
    order, tools = JOB_ORDER[package], TOOLS.get(package, {})
    dotted = package.replace("/", ".")
    assert sorted(p.stem for p in (ROOT / package).glob("*.py")) == sorted((*order, *tools, "__init__"))
    allowed = {dotted} | {f"{dotted}.{m}" for m in INIT_IMPORTS.get(package, ())}
    assert not [n for _line, n in imported(ROOT / package / "__init__.py") if n not in allowed]
    modules = [(job, order[:i]) for i, job in enumerate(order)]
    modules += [(tool, order[:order.index(last) + 1]) for tool, last in tools.items()]
    for module, before in modules:
        for line, name in imported(ROOT / package / f"{module}.py"):
            if name.startswith(dotted + "."):
                other = name[len(dotted) + 1:].split(".")[0]
                assert other in before, f"{package}/{module}.py:{line} imports {name}: {other} is not before {module}"


def test_the_viewer_draws_a_rooms_landmarks_through_its_hook() -> None:
    """The viewer names no mission: paper 000's report registers its landmark kind
    (dashboards/rerun_bodies.py `register_landmark_kind`), which the viewer finds when it reads a
    run's configuration (and no kind before the reports are loaded)."""
    assert "p000_landmark" not in (ROOT / "dashboards" / "rerun_bodies.py").read_text()  # the names are the contract's
    code = ("import json\nfrom swarmhil.dashboards.rerun_bodies import LANDMARK_KINDS, SceneSpec\nbefore = dict(LANDMARK_KINDS)\n"
            "s = SceneSpec.from_config({'sensing': {'kind': 'p000-landmarks', 'params': {'range_m': 7.0}}})\n"
            "print(json.dumps([before, s.landmark_kind, s.cone, LANDMARK_KINDS['p000-landmarks']]))")
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    before, kind, cone, names = json.loads(p.stdout)
    assert before == {} and kind == "p000-landmarks" and cone[1] == 7.0
    assert names == ["p000_landmarks_body_m", "p000_landmark_ids"]


def absolute_imports(path: Path) -> Iterator[tuple[int, str]]:
    """(line, module) of every absolute import statement and literal `import_module` name of a file."""
    levels = ast_levels(path)
    for line, name in imported_as_written(path):
        if name.split(".")[0] not in set(FOLDERS) or levels.get(line, 0) == 0:
            yield line, name


def ast_levels(path: Path) -> dict[int, int]:
    """{line: the relative level of the first `from` import statement on it} of a file (a line not in
    it: absolute or not a statement), from one walk of its tree."""
    levels: dict[int, int] = {}
    for node in ast.walk(parsed(path)):
        if isinstance(node, ast.ImportFrom):
            levels.setdefault(node.lineno, node.level)
    return levels


def test_the_project_imports_itself_through_the_namespace_only() -> None:
    """Every import of a project module names it under `swarmhil.` (the installed name), in the
    product, the tests, the benches and the claims; a bare `import agent...` would load a second copy
    of the module from the repository's folder (or fail where the wheel is installed)."""
    files = [p for top in (*FOLDERS, "tests", "bench") for p in sources(top) if ".browser" not in p.parts]
    bare = [f"{p.relative_to(ROOT)}:{line}: {name}" for p in files for line, name in absolute_imports(p)
            if name.split(".")[0] in set(FOLDERS) - {NAMESPACE}]
    assert not bare, bare
    assert short("swarmhil.agent.node") == "agent.node" and short("swarmhil.claims") == "claims"
    assert short("agent.node") == "agent.node" and short("swarmhil") == "swarmhil"
