"""Bad input on the command line (issue 17): one clear line naming the problem, a non-zero exit
code, never a traceback. A table of cases, each run through the `swarmhil` click entry point."""
from __future__ import annotations

import os
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import SCENARIOS
from deploy.cli import main

DEMO = str(SCENARIOS / "demo.toml")
MAGIC = b"\x89MCAP0\r\n"


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bad")
    f = {"d": d}
    f["latin1"] = d / "latin1.toml"
    f["latin1"].write_bytes(b'[run]\nname = "caf\xe9"\n')
    f["garbage"] = d / "garbage.mcap"
    f["garbage"].write_bytes(os.urandom(3000))
    f["garbage_dir"] = d / "garbage_run"
    f["garbage_dir"].mkdir()
    (f["garbage_dir"] / "run.mcap").write_bytes(os.urandom(3000))
    # a real recording cut short (its writer killed mid-file): header and a bit, no footer
    res = CliRunner().invoke(main, ["run", DEMO, "--in-process", "--duration", "100", "--out", str(d / "good"), "--no-progress"])
    assert res.exit_code == 0, res.output
    f["good"] = d / "good"
    data = (d / "good" / "run.mcap").read_bytes()
    f["truncated"] = d / "truncated.mcap"
    f["truncated"].write_bytes(data[:300])
    f["truncated_dir"] = d / "truncated_run"
    f["truncated_dir"].mkdir()
    (f["truncated_dir"] / "run.mcap").write_bytes(data[:300])
    return f


CASES = [
    ("non-UTF-8 TOML", lambda f: ["run", str(f["latin1"]), "--in-process"], "not UTF-8"),
    ("negative seed", lambda f: ["run", DEMO, "--in-process", "--seed", "-1", "--out", str(f["d"] / "x1")], "--seed"),
    ("bad run id", lambda f: ["run", DEMO, "--in-process", "--run-id", "a/b*", "--out", str(f["d"] / "x2")], "--run-id"),
    ("unwritable out", lambda f: ["run", DEMO, "--in-process", "--out", "/proc/swarmhil-no/such"], "--out"),
    ("max_tries negative", lambda f: ["run", DEMO, "--in-process", "--set", "dispersion.max_tries=-3", "--out", str(f["d"] / "x3")], "max_tries"),
    ("max_tries not a number", lambda f: ["run", DEMO, "--in-process", "--set", "dispersion.max_tries=abc", "--out", str(f["d"] / "x4")], "max_tries"),
    ("duration below a step", lambda f: ["run", DEMO, "--in-process", "--duration", "1", "--out", str(f["d"] / "x5")], "--duration"),
    ("endless duration", lambda f: ["run", DEMO, "--in-process", "--set", "run.duration_s=1e300", "--out", str(f["d"] / "x6")], "steps"),
    ("out holds a run", lambda f: ["run", DEMO, "--in-process", "--duration", "20", "--out", str(f["good"])], "already holds a run"),
    ("record truth multi-process", lambda f: ["run", DEMO, "--record", "truth", "--out", str(f["d"] / "x7")], "--in-process"),
    ("mcap info garbage", lambda f: ["mcap", "info", str(f["garbage"])], "garbage.mcap"),
    ("mcap info truncated", lambda f: ["mcap", "info", str(f["truncated"])], "mcap repair"),
    ("report garbage", lambda f: ["report", str(f["garbage_dir"])], "garbage_run"),
    ("report truncated", lambda f: ["report", str(f["truncated_dir"])], "truncated_run"),
    ("report-bandwidth garbage", lambda f: ["report-bandwidth", str(f["garbage_dir"])], "garbage_run"),
    ("report-bandwidth truncated", lambda f: ["report-bandwidth", str(f["truncated_dir"])], "truncated_run"),
    ("mcap repair garbage", lambda f: ["mcap", "repair", str(f["garbage"]), str(f["d"] / "fixed.mcap")], "not an MCAP"),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_and_a_non_zero_exit(files: dict[str, Path], case) -> None:
    _name, argv, needle = case
    res = CliRunner().invoke(main, argv(files))
    assert res.exit_code != 0, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    err = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(err) == 1 and "Traceback" not in res.output, res.output
    assert needle in err[0], err[0]


def test_overwrite_replaces_a_run(files: dict[str, Path]) -> None:
    out = files["d"] / "again"
    args = ["run", DEMO, "--in-process", "--duration", "20", "--out", str(out), "--no-progress"]
    assert CliRunner().invoke(main, args).exit_code == 0
    (out / "agents").mkdir(exist_ok=True)
    (out / "agents" / "stale.json").write_text("{}")
    assert CliRunner().invoke(main, args).exit_code == 2
    res = CliRunner().invoke(main, [*args, "--overwrite"])
    assert res.exit_code == 0, res.output
    assert not (out / "agents" / "stale.json").exists()
