"""`swarmhil image wheelhouse|base|build`: the compose projects' container image without a registry or an
index (deploy/image.py, docs/containers.md)."""
from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import click

from swarmhil.deploy.image import BASE_TAG, base_rootfs, build, import_base, wheelhouse


@click.group()
def image() -> None:
    """The container image of compose projects, without a registry or an index (docs/containers.md)."""


def _docker_step(step: Any) -> Any:
    """A step of deploy/image.py: a program that fails or is missing is one line, exit 1."""
    try:
        return step()
    except subprocess.CalledProcessError as exc:
        raise click.ClickException(f"{' '.join(map(str, exc.cmd))[:300]} failed (exit {exc.returncode})") from None
    except (FileNotFoundError, RuntimeError) as exc:
        raise click.ClickException(str(exc)) from None


_DOCKER = click.option("--docker", default="docker", show_default=True,
                       help="The Docker client (its engine: $DOCKER_HOST or the default socket).")
_EXTRAS = click.option("--extras", default="", metavar="'[camera]'", help="The package extras to install (default: core only).")


@image.command("wheelhouse")
@click.argument("out", type=click.Path(file_okay=False))
@_EXTRAS
def image_wheelhouse(out: str, extras: str) -> None:
    """Fill OUT with every wheel the image installs (pip wheel of this checkout at constraints.txt; needs an index)."""
    path = _docker_step(lambda: wheelhouse(Path(out), extras))
    click.echo(f"wrote {len(list(path.glob('*.whl')))} wheels to {path}")


@image.command("base")
@click.option("--rootfs", default="build/base-rootfs.tar", show_default=True, type=click.Path(dir_okay=False),
              help="The debootstrap root file system (made if missing; as root, from a Debian mirror).")
@click.option("--tag", default=BASE_TAG, show_default=True)
@_DOCKER
def image_base(rootfs: str, tag: str, docker: str) -> None:
    """A base image with Python 3.11 and pip from Debian packages, no container registry (debootstrap + docker import)."""
    click.echo(f"base image {_docker_step(lambda: import_base([docker], base_rootfs(Path(rootfs)), tag))}")


@image.command("build")
@click.option("--tag", default="swarmhil:latest", show_default=True)
@click.option("--base", help="The base image (default: the Dockerfile's, python:3.11.7-slim-bookworm).")
@click.option("--wheelhouse", "wheels", type=click.Path(exists=True, file_okay=False),
              help="Install from these wheels alone (`swarmhil image wheelhouse`): no index, no network in the build.")
@_EXTRAS
@_DOCKER
def image_build(tag: str, base: str | None, wheels: str | None, extras: str, docker: str) -> None:
    """Build deploy/Dockerfile from this checkout (only the files it copies are sent to the engine)."""
    _docker_step(lambda: build([docker], tag, base=base, wheels=Path(wheels) if wheels else None, extras=extras))
    click.echo(f"built {tag}" + (f" offline from {wheels}" if wheels else ""))
