"""An agent's CPU budget (issue 26, docs/hil.md): `[[spacecraft]] cpu_fraction = F` runs that agent's
process as on a flight computer with F of one of this machine's cores, with the operating system's
CPU quota (Linux cgroups, CFS bandwidth control).

cgroup v1 (`/sys/fs/cgroup/cpu/`, what these machines mount): a group `swarmhil-<run>-<process>`
with `cpu.cfs_quota_us = F * cpu.cfs_period_us`; cgroup v2 (`/sys/fs/cgroup/cgroup.controllers`
lists `cpu`): the same group with `cpu.max = "QUOTA PERIOD"`. The period is short (10 ms, longer
only so that the quota stays >= 1 ms, the kernel's minimum), so a step's computation is slowed
evenly rather than in one long stall. Where a group cannot be made (no root, no cpu controller, not
Linux) the budget is not enforced and the launcher says so in one line. The launcher removes the
group once the process has exited.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path("/sys/fs/cgroup")
PERIOD_US = 10_000
MIN_QUOTA_US = 1_000


def period_quota_us(fraction: float) -> tuple[int, int]:
    """(period, quota) in microseconds for `fraction` of one core: quota / period = fraction."""
    period = max(PERIOD_US, int(round(MIN_QUOTA_US / fraction)))
    return period, max(MIN_QUOTA_US, int(round(fraction * period)))


@dataclass
class CpuBudget:
    """One process's budget: its group (None when not enforced) and why not."""

    process: str
    fraction: float
    group: Path | None
    why_not: str = ""

    def stats(self) -> dict[str, Any]:
        """The group's throttling counters (cgroup v1 cpu.stat: nr_periods, nr_throttled,
        throttled_time ns; v2: nr_periods, nr_throttled, throttled_usec)."""
        if self.group is None:
            return {}
        try:
            return {k: int(v) for k, v in (line.split() for line in (self.group / "cpu.stat").read_text().splitlines())}
        except (OSError, ValueError):
            return {}

    def summary(self) -> dict[str, Any]:
        period, quota = period_quota_us(self.fraction)
        return {"fraction": self.fraction, "enforced": self.group is not None, "period_us": period, "quota_us": quota,
                "group": str(self.group) if self.group else None, "why_not": self.why_not, "cpu_stat": self.stats()}


def _group(run: str, process: str, fraction: float, root: Path) -> Path:
    """Make (or reuse) the quota group of `fraction` of one core; OSError where the machine does not allow it."""
    period, quota = period_quota_us(fraction)
    v2 = (root / "cgroup.controllers").is_file()
    base = root if v2 else root / "cpu"
    if v2 and "cpu" not in (root / "cgroup.controllers").read_text().split():
        raise OSError(f"{root}/cgroup.controllers has no cpu controller")
    if not v2 and not (base / "cpu.cfs_quota_us").is_file():
        raise OSError(f"no cgroup v1 cpu controller at {base}")
    group = base / f"swarmhil-{run}-{process}"
    group.mkdir(exist_ok=True)
    if v2:
        (group / "cpu.max").write_text(f"{quota} {period}\n")
    else:
        (group / "cpu.cfs_period_us").write_text(f"{period}\n")
        (group / "cpu.cfs_quota_us").write_text(f"{quota}\n")
    return group


def _why(exc: OSError) -> str:
    return f"{exc.strerror or exc}" + (f" ({exc.filename})" if getattr(exc, "filename", None) else "")


def limit(run: str, process: str, pid: int, fraction: float, root: Path = ROOT) -> CpuBudget:
    """Put `pid` (> 0) in a CPU-quota group of `fraction` of one core (made if needed); a CpuBudget
    whose `why_not` says why not when the machine does not allow it."""
    if pid <= 0:  # (cgroup.procs reads 0 as "the writer itself")
        raise ValueError(f"pid must be > 0 (got {pid})")
    group = None
    try:
        group = _group(run, process, fraction, root)
        (group / "cgroup.procs").write_text(f"{pid}\n")
    except OSError as exc:
        release(CpuBudget(process, fraction, group))
        return CpuBudget(process, fraction, None, _why(exc))
    return CpuBudget(process, fraction, group)


def available(root: Path = ROOT) -> str | None:
    """None when budgets can be enforced here (a quota group can be made and removed), else why not."""
    import os

    try:
        group = _group("probe", str(os.getpid()), 0.5, root)
    except OSError as exc:
        return _why(exc)
    group.rmdir()
    return None


def release(budget: CpuBudget) -> None:
    """Remove the group (its processes have exited); a group still busy stays (the kernel refuses)."""
    if budget.group is not None:
        try:
            budget.group.rmdir()
        except OSError:
            pass
