"""What the command line checks of its input files before it reads them (docs/cli.md).

Each check returns None or the problem in a few words, so every subcommand refuses a missing,
empty, truncated or garbage recording or run directory with one line naming it (exit code 1;
a path that does not exist at all is a usage error, exit code 2, from click). Standard library only.
"""
from __future__ import annotations

import json
from pathlib import Path

import click

MCAP_MAGIC = b"\x89MCAP0\r\n"


def recording_problem(path: str | Path) -> str | None:
    """None for a file that starts and ends with the MCAP magic; else what is wrong with it."""
    p = Path(path)
    if not p.exists():
        return "does not exist"
    if p.is_dir():
        return "is a directory, not an MCAP recording"
    try:
        size = p.stat().st_size
        with open(p, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
            f.seek(max(0, size - len(MCAP_MAGIC)))
            tail = f.read(len(MCAP_MAGIC))
    except OSError as exc:
        return f"cannot be read ({exc.strerror or exc})"
    if size == 0:
        return "is empty (0 bytes)"
    if head != MCAP_MAGIC:
        return "is not an MCAP recording (no MCAP magic at the start)"
    if size < 2 * len(MCAP_MAGIC) or tail != MCAP_MAGIC:
        return (f"is cut short ({size} bytes, no MCAP footer: was its writer killed?); "
                f"`swarmhil mcap repair {p} FIXED.mcap` salvages its complete chunks")
    return None


def run_dir_problem(path: str | Path) -> str | None:
    """None for a directory with a readable-looking run.mcap; else what is wrong with it."""
    d = Path(path)
    if not d.exists():
        return "does not exist"
    if not d.is_dir():
        return "is a file, not a run directory (give the directory that holds run.mcap)"
    if not (d / "run.mcap").exists():
        return "has no run.mcap: not a run directory"
    problem = recording_problem(d / "run.mcap")
    if problem:
        return f"run.mcap {problem}"
    for name in ("summary.json", "scenario.json"):  # written by the run; a report reads them when present
        if (d / name).is_file():
            try:
                json.loads((d / name).read_text(encoding="utf-8"))
            except (OSError, UnicodeDecodeError, ValueError) as exc:
                return f"{name} is not readable JSON ({' '.join(str(exc).split())[:120]}); remove it or run again"
    return None


def check_recording(path: str | Path) -> None:
    """Refuse a bad recording: one line naming it, exit code 1."""
    problem = recording_problem(path)
    if problem:
        raise click.ClickException(f"{path}: {problem}")


def check_run_dir(path: str | Path) -> None:
    """Refuse a bad run directory: one line naming it, exit code 1."""
    problem = run_dir_problem(path)
    if problem:
        raise click.ClickException(f"{path}: {problem}")
