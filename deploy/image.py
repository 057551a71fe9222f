"""The project's container image built without a registry or a package index (issue 28; docs/containers.md).

Three steps, each usable alone (`swarmhil image ...`, or from a test):

- `base_rootfs`: a Debian root file system with Python 3.11 and pip, made by `debootstrap
  --variant=minbase` from a Debian mirror (no container registry), saved as a tar; `import_base`
  turns it into an image (`docker import`) whose pip may install system-wide
  (PIP_BREAK_SYSTEM_PACKAGES: the image is the environment). Any image with Python 3.11 and pip
  serves as well (`--base`; the Dockerfile's default is python:3.11.7-slim-bookworm).
- `wheelhouse`: on a host that can reach an index, `pip wheel` of the project and all its
  dependencies at the versions of constraints.txt into a folder (the project's own wheel included,
  built from the checkout's sdist: a `build/` folder left in the checkout can hold modules since
  moved or deleted, which a wheel built in the tree would carry).
- `build`: `docker build -f deploy/Dockerfile` in a context staged from the checkout (only what the
  Dockerfile copies, and the wheelhouse), with `--build-arg WHEELHOUSE=wheelhouse` the install
  reads the wheelhouse alone (`pip install --no-index`) and `--network none` gives the build no
  network at all. The legacy builder (DOCKER_BUILDKIT=0): Debian's docker.io has no buildx.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCKERFILE = ROOT / "deploy" / "Dockerfile"
BASE_TAG = "local/python:3.11-bookworm"
BASE_SUITE = "bookworm"
BASE_PACKAGES = ("python3", "python3-pip", "python-is-python3", "passwd")
DEBIAN_MIRROR = "http://deb.debian.org/debian"
# what deploy/Dockerfile copies from its context, besides the wheelhouse
CONTEXT = ("pyproject.toml", "constraints.txt", "README.md", "agent", "plant", "bus", "link", "missions", "deploy",
           "dashboards", "claims", "swarmhil")  # swarmhil/: the namespace's __init__ and its links to the folders
WHEELHOUSE_IN_CONTEXT = "wheelhouse"


def _run(argv: list[str], **kw: object) -> None:
    subprocess.run(argv, check=True, **kw)  # type: ignore[call-overload]


def mounts_under(path: Path) -> list[str]:
    """The mount points at or below `path` (a tree with any must not be deleted recursively)."""
    return [ln.split()[1] for ln in Path("/proc/self/mounts").read_text().splitlines()
            if ln.split()[1] == str(path) or ln.split()[1].startswith(f"{path}/")]


def base_rootfs(tar: Path, *, mirror: str = DEBIAN_MIRROR) -> Path:
    """`tar`: a minbase Debian with Python and pip (debootstrap, as root; 163 s at load 8, 196 MB). Kept if present."""
    if tar.exists():
        return tar
    tar.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="swarmhil-rootfs-", dir=tar.parent))
    rootfs = work / "rootfs"
    try:
        _run(["debootstrap", "--variant=minbase", f"--include={','.join(BASE_PACKAGES)}", BASE_SUITE, str(rootfs),
              mirror], stdout=subprocess.DEVNULL)
        for junk in ("var/cache/apt/archives", "var/lib/apt/lists"):
            for f in (rootfs / junk).glob("*"):
                if f.is_file():
                    f.unlink()
        tmp = tar.with_suffix(".tmp")
        _run(["tar", "-C", str(rootfs), "--numeric-owner", "-cf", str(tmp), "."])
        tmp.replace(tar)
    finally:
        # never delete through a mount debootstrap left (its /proc, a bound /dev): the host's files
        mounts = mounts_under(work)
        if mounts:
            raise RuntimeError(f"debootstrap left mounts under {work}: {' '.join(mounts)} (unmount, then delete it)")
        shutil.rmtree(work)
    return tar


def import_base(docker: list[str], tar: Path, tag: str = BASE_TAG) -> str:
    """The rootfs tar as image `tag` (`docker import`), unless an image of that name exists."""
    if subprocess.run([*docker, "image", "inspect", tag], capture_output=True).returncode == 0:
        return tag
    _run([*docker, "import", "--change", "ENV PIP_BREAK_SYSTEM_PACKAGES=1", "--change", 'CMD ["python3"]', str(tar),
          tag], stdout=subprocess.DEVNULL)
    return tag


def sdist_tree(dest: Path) -> Path:
    """This checkout's sdist (setuptools' PEP 517 `build_sdist`, as `python -m build` makes it first)
    unpacked under `dest`: the source tree a wheel is built from, with only what the sdist lists."""
    dest.mkdir(parents=True, exist_ok=True)
    code = "import sys; from setuptools import build_meta as b; print(b.build_sdist(sys.argv[1]))"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    r = subprocess.run([sys.executable, "-c", code, str(dest)], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=300)
    if r.returncode != 0:
        raise RuntimeError(f"building the sdist of {ROOT} failed:\n{r.stdout[-2000:]}{r.stderr[-3000:]}")
    with tarfile.open(dest / r.stdout.split()[-1]) as tf:
        tf.extractall(dest / "src", filter="data")
    return next((dest / "src").iterdir())


def wheelhouse(out: Path, extras: str = "") -> Path:
    """Every wheel the image installs (the project's, built from the sdist, and its dependencies' at
    constraints.txt) into `out`."""
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("swarmhil-*.whl"):  # the project's own wheel is rebuilt from this checkout
        old.unlink()
    with tempfile.TemporaryDirectory() as d:
        _run([sys.executable, "-m", "pip", "wheel", "-q", "--wheel-dir", str(out), "--find-links", str(out),
              f"{sdist_tree(Path(d))}{extras}", "-c", str(ROOT / "constraints.txt")])
    return out


def stage_context(dest: Path, wheels: Path | None) -> Path:
    """A build context with only what the Dockerfile copies (no venv, runs or caches), and the wheelhouse."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in CONTEXT:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, dest / name, ignore=ignore, symlinks=True)  # swarmhil/<folder> stays a link
        else:
            shutil.copy2(src, dest / name)
    if wheels is not None:
        shutil.copytree(wheels, dest / WHEELHOUSE_IN_CONTEXT)
    return dest


def build_command(docker: list[str], context: Path, tag: str, *, base: str | None, offline: bool,
                  extras: str = "") -> list[str]:
    argv = [*docker, "build", "-q", "-f", str(context / "deploy" / "Dockerfile"), "-t", tag]
    if base:
        argv += ["--build-arg", f"BASE={base}"]
    if extras:
        argv += ["--build-arg", f"EXTRAS={extras}"]
    if offline:  # the install reads the wheelhouse alone, and no step of the build has a network
        argv += ["--build-arg", f"WHEELHOUSE={WHEELHOUSE_IN_CONTEXT}", "--network", "none"]
    return [*argv, str(context)]


def build(docker: list[str], tag: str, *, base: str | None = None, wheels: Path | None = None,
          extras: str = "") -> None:
    """The project image `tag`; with `wheels` offline (no index, no network in the build)."""
    with tempfile.TemporaryDirectory(prefix="swarmhil-image-") as d:
        ctx = stage_context(Path(d), wheels)
        _run(build_command(docker, ctx, tag, base=base, offline=wheels is not None, extras=extras),
             env={**os.environ, "DOCKER_BUILDKIT": "0"}, stdout=subprocess.DEVNULL)
