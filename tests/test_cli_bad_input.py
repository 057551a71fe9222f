"""Bad input on the command line (issues 17, 18): one clear line naming the problem, the exit code
of docs/cli.md (1: a file that cannot be read, 2: a bad option, argument or scenario, 3: not enough
memory), never a traceback. A table of cases over every subcommand and every kind of bad input
(missing, empty, truncated, garbage scenario files, run directories and recordings), each run
through the `swarmhil` click entry point."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import ROOT, SCENARIOS
from swarmhil.deploy.cli import main

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
    # scenario files: missing, empty, cut inside a string, random bytes, a directory
    f["no_toml"] = d / "missing.toml"
    f["empty_toml"] = d / "empty.toml"
    f["empty_toml"].write_bytes(b"")
    text = Path(DEMO).read_bytes()
    f["cut_toml"] = d / "cut.toml"
    f["cut_toml"].write_bytes(text[:text.index(b'"demo"') + 3])
    f["garbage_toml"] = d / "garbage.toml"
    f["garbage_toml"].write_bytes(b"\xff\xfe" + os.urandom(2000))
    f["toml_dir"] = d / "a_dir.toml"
    f["toml_dir"].mkdir()
    # recordings: missing, empty; run directories: missing, without run.mcap, with an empty one,
    # with a garbage summary.json
    f["no_mcap"] = d / "missing.mcap"
    f["empty_mcap"] = d / "empty.mcap"
    f["empty_mcap"].write_bytes(b"")
    f["no_run"] = d / "missing_run"
    f["not_run"] = d / "not_a_run"
    f["not_run"].mkdir()
    f["empty_run"] = d / "empty_run"
    f["empty_run"].mkdir()
    (f["empty_run"] / "run.mcap").write_bytes(b"")
    f["bad_summary"] = d / "bad_summary_run"
    f["bad_summary"].mkdir()
    (f["bad_summary"] / "run.mcap").write_bytes(data)
    (f["bad_summary"] / "summary.json").write_text('{"run": "x", "metr')
    f["bad_campaign"] = d / "bad_campaign"
    f["bad_campaign"].mkdir()
    (f["bad_campaign"] / "campaign.json").write_bytes(os.urandom(100))
    return f


def _scenario_cases() -> list:
    """Every scenario-reading subcommand on every kind of bad scenario file: exit code 2."""
    cmds = {
        "run": lambda p, f: ["run", p, "--in-process", "--out", str(f["d"] / "never")],
        "sweep": lambda p, f: ["sweep", p, "--param", "run.seed", "--values", "1", "--out", str(f["d"] / "never")],
        "campaign": lambda p, f: ["campaign", p, "--seeds", "1", "--out", str(f["d"] / "never")],
        "compose": lambda p, f: ["compose", p, "--out", str(f["d"] / "never.yml")],
        "scale": lambda p, f: ["scale", p, "100", "--out", str(f["d"] / "never-scaled.toml")],
    }
    kinds = {"missing": ("no_toml", "missing.toml"), "empty": ("empty_toml", "no spacecraft"),
             "cut short": ("cut_toml", "not valid TOML"), "garbage": ("garbage_toml", "not UTF-8"),
             "a directory": ("toml_dir", "a_dir.toml")}
    return [(f"{c} {k} scenario", (lambda cmd, key: lambda f: cmd(str(f[key]), f))(cmd, key), needle, 2)
            for c, cmd in cmds.items() for k, (key, needle) in kinds.items()]


def _recording_cases() -> list:
    """Every recording-reading subcommand on a missing (2), empty, truncated or garbage (1) MCAP."""
    cmds = {
        "mcap info": lambda p, f: ["mcap", "info", p],
        "mcap repair": lambda p, f: ["mcap", "repair", p, str(f["d"] / "fixed.mcap")],
        "replay": lambda p, f: ["replay", p, "--rrd", str(f["d"] / "never.rrd")],
    }
    kinds = {"missing": ("no_mcap", "missing.mcap", 2), "empty": ("empty_mcap", "empty (0 bytes)", 1),
             "truncated": ("truncated", "truncated.mcap", 1), "garbage": ("garbage", "not an MCAP recording", 1)}
    return [(f"{c} {k} recording", (lambda cmd, key: lambda f: cmd(str(f[key]), f))(cmd, key), needle, code)
            for c, cmd in cmds.items() for k, (key, needle, code) in kinds.items()]


def _run_dir_cases() -> list:
    """Every run-directory-reading subcommand on a missing directory (2), a file, a directory without
    run.mcap, with an empty, truncated or garbage one, or a garbage summary.json (1)."""
    cmds = {
        "report": lambda p, f: ["report", p],
        "report-bandwidth": lambda p, f: ["report-bandwidth", p],
        "report-nav": lambda p, f: ["report-nav", p, "--out", str(f["d"] / "nav")],
        "refly": lambda p, f: ["refly", p, "--agent", "sc01", "--out", str(f["d"] / "refly")],
    }
    kinds = {"missing": ("no_run", "missing_run", 2), "a file": ("empty_mcap", "empty.mcap", 2),
             "no run.mcap": ("not_run", "has no run.mcap", 1), "empty": ("empty_run", "run.mcap is empty", 1),
             "truncated": ("truncated_dir", "cut short", 1), "garbage": ("garbage_dir", "not an MCAP recording", 1),
             "garbage summary": ("bad_summary", "summary.json is not readable JSON", 1)}
    return [(f"{c} {k} run dir", (lambda cmd, key: lambda f: cmd(str(f[key]), f))(cmd, key), needle, code)
            for c, cmd in cmds.items() for k, (key, needle, code) in kinds.items()]


CASES = [
    ("non-UTF-8 TOML", lambda f: ["run", str(f["latin1"]), "--in-process"], "not UTF-8", 2),
    ("negative seed", lambda f: ["run", DEMO, "--in-process", "--seed", "-1", "--out", str(f["d"] / "x1")], "--seed", 2),
    ("bad run id", lambda f: ["run", DEMO, "--in-process", "--run-id", "a/b*", "--out", str(f["d"] / "x2")], "--run-id", 2),
    ("unwritable out", lambda f: ["run", DEMO, "--in-process", "--out", "/proc/swarmhil-no/such"], "--out", 2),
    ("max_tries negative", lambda f: ["run", DEMO, "--in-process", "--set", "dispersion.max_tries=-3", "--out", str(f["d"] / "x3")], "max_tries", 2),
    ("max_tries not a number", lambda f: ["run", DEMO, "--in-process", "--set", "dispersion.max_tries=abc", "--out", str(f["d"] / "x4")], "max_tries", 2),
    ("duration below a step", lambda f: ["run", DEMO, "--in-process", "--duration", "1", "--out", str(f["d"] / "x5")], "--duration", 2),
    ("endless duration", lambda f: ["run", DEMO, "--in-process", "--set", "run.duration_s=1e300", "--out", str(f["d"] / "x6")], "steps", 2),
    ("out holds a run", lambda f: ["run", DEMO, "--in-process", "--duration", "20", "--out", str(f["good"])], "already holds a run", 2),
    ("record truth multi-process", lambda f: ["run", DEMO, "--record", "truth", "--out", str(f["d"] / "x7")], "--in-process", 2),
    ("mcap info garbage", lambda f: ["mcap", "info", str(f["garbage"])], "garbage.mcap", 1),
    ("mcap info truncated", lambda f: ["mcap", "info", str(f["truncated"])], "mcap repair", 1),
    ("report garbage", lambda f: ["report", str(f["garbage_dir"])], "garbage_run", 1),
    ("report truncated", lambda f: ["report", str(f["truncated_dir"])], "truncated_run", 1),
    ("report-bandwidth garbage", lambda f: ["report-bandwidth", str(f["garbage_dir"])], "garbage_run", 1),
    ("report-bandwidth truncated", lambda f: ["report-bandwidth", str(f["truncated_dir"])], "truncated_run", 1),
    ("mcap repair garbage", lambda f: ["mcap", "repair", str(f["garbage"]), str(f["d"] / "fixed.mcap")], "not an MCAP", 1),
    ("drift-null gain not a number", lambda f: ["run", DEMO, "--in-process", "--set", 'controller.params.gain_per_s="x"',
                                                "--out", str(f["d"] / "x7")], "gain_per_s", 2),
    ("drift-null gain NaN", lambda f: ["run", DEMO, "--in-process", "--set", "controller.params.gain_per_s=nan",
                                       "--out", str(f["d"] / "x8")], "gain_per_s", 2),
    ("unknown option", lambda f: ["run", DEMO, "--no-such-option"], "--no-such-option", 2),
    ("unknown subcommand", lambda f: ["fly", DEMO], "fly", 2),
    ("sweep seeds not integers", lambda f: ["sweep", DEMO, "--param", "run.seed", "--values", "1", "--seeds", "a,b"], "--seeds", 2),
    ("sweep unknown param", lambda f: ["sweep", DEMO, "--param", "nosuch.field", "--values", "1"], "nosuch", 2),
    ("campaign zero seeds", lambda f: ["campaign", DEMO, "--seeds", "0"], "--seeds", 2),
    ("report-nav labels mismatch", lambda f: ["report-nav", str(f["good"]), "--out", str(f["d"] / "nav"), "--label", "a",
                                              "--label", "b"], "--label", 2),
    ("report-bandwidth compare garbage", lambda f: ["report-bandwidth", str(f["good"]), "--compare", str(f["garbage_dir"])],
     "garbage_run", 1),
    ("campaign garbage record in --out", lambda f: ["campaign", DEMO, "--seeds", "1", "--out", str(f["bad_campaign"])],
     "campaign.json", 2),
    ("campaign-compare missing dir", lambda f: ["campaign-compare", str(f["no_run"]), str(f["not_run"])], "missing_run", 2),
    ("campaign-compare not a campaign", lambda f: ["campaign-compare", str(f["not_run"]), str(f["not_run"])],
     "not a campaign directory", 2),
    ("campaign-compare garbage campaign.json", lambda f: ["campaign-compare", str(f["bad_campaign"]), str(f["bad_campaign"])],
     "unreadable", 2),
    ("campaign-compare one label", lambda f: ["campaign-compare", str(f["bad_campaign"]), str(f["bad_campaign"]), "--label", "a"],
     "--label", 2),
    ("demo unwritable out", lambda f: ["demo", "--out", "/proc/swarmhil-no/such"], "--out", 2),
    ("demo unknown option", lambda f: ["demo", "--speed", "3"], "--speed", 2),
    ("bad restart policy", lambda f: ["run", DEMO, "--in-process", "--set", 'supervision.restart="always"', "--out", str(f["d"] / "x9")], "[supervision].restart", 2),
    ("dead_after_missed is gone", lambda f: ["run", DEMO, "--in-process", "--set", "time.dead_after_missed=3", "--out", str(f["d"] / "x10")], "dead_after_missed", 2),
    ("mcap merge garbage", lambda f: ["mcap", "merge", str(f["garbage"]), str(f["d"] / "merged.mcap")], "not an MCAP", 1),
    ("mcap merge without output", lambda f: ["mcap", "merge", str(f["truncated"])], "output file", 1),
    ("router without secrets", lambda f: ["router", "--listen", "tcp/127.0.0.1:9", "--acl-dir", str(f["d"])], "secrets directory", 2),
    ("claims unknown option", lambda f: ["claims", "--no-such-tier"], "--no-such-tier", 2),
    ("compose external spacecraft", lambda f: ["compose", str(SCENARIOS / "hil-3.toml"), "--out", str(f["d"] / "c.yml")],
     "external flight software", 2),
    ("scale past 1000", lambda f: ["scale", str(SCENARIOS / "sabatini-20.toml"), "1001", "--out", str(f["d"] / "s.toml")],
     "[dispersion].count must be an integer in 1..1000", 2),
    ("scale explicit spacecraft", lambda f: ["scale", str(SCENARIOS / "sabatini-20-explicit.toml"), "100", "--out",
                                             str(f["d"] / "s.toml")], "no [dispersion] table", 2),
    ("image wheelhouse into a file", lambda f: ["image", "wheelhouse", str(f["garbage"])], "OUT", 2),
    ("image base without docker", lambda f: ["image", "base", "--rootfs", str(f["garbage"]), "--docker",
                                             str(f["d"] / "no-docker")], "no-docker", 1),
    ("image build missing wheelhouse", lambda f: ["image", "build", "--wheelhouse", str(f["d"] / "no-wheels")],
     "--wheelhouse", 2),
    ("image build without docker", lambda f: ["image", "build", "--docker", str(f["d"] / "no-docker")], "no-docker", 1),
    ("hosts in-process", lambda f: ["run", DEMO, "--in-process", "--hosts", "2", "--out", str(f["d"] / "x11")],
     "--hosts needs a multi-process run", 2),
    ("hosts zero", lambda f: ["run", DEMO, "--hosts", "0", "--out", str(f["d"] / "x12")], "--hosts", 2),
    ("netns on one host", lambda f: ["run", DEMO, "--netns", "--out", str(f["d"] / "x14")], "--netns needs --hosts 2", 2),
    ("spacecraft on an unknown host", lambda f: ["run", str(SCENARIOS / "sabatini-20-explicit.toml"), "--hosts", "2", "--set",
                                                 "spacecraft.1.host=2", "--out", str(f["d"] / "x13")],
     "sc02: host = 2, but the run has 2 hosts", 2),
    ("claims unwritable json", lambda f: ["claims", "--check-docs", "--json", "/proc/swarmhil-no/such"], "--json", 2),
    ("claims lower-baseline without prose", lambda f: ["claims", "--lower-baseline"], "--lower-baseline goes with --prose", 2),
    *_scenario_cases(), *_recording_cases(), *_run_dir_cases(),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_and_a_documented_exit_code(files: dict[str, Path], case) -> None:
    _name, argv, needle, code = case
    res = CliRunner().invoke(main, argv(files))
    assert res.exit_code == code, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    err = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(err) == 1 and "Traceback" not in res.output, res.output
    assert err[0].startswith("error: ") and needle in err[0], err[0]


def test_every_subcommand_is_in_the_table() -> None:
    """A new subcommand needs its bad-input cases here (and its rows in docs/cli.md)."""
    def leaves(group, prefix=""):  # type: ignore[no-untyped-def]
        for name, cmd in group.commands.items():
            yield from leaves(cmd, f"{prefix}{name} ") if hasattr(cmd, "commands") else [f"{prefix}{name}"]
    tested = {c[0] for c in CASES}
    doc = (ROOT / "docs" / "cli.md").read_text()
    for cmd in leaves(main):
        assert any(t.startswith(cmd + " ") for t in tested), f"no bad-input case for `{cmd}`"
        assert f"`{cmd}`" in doc, f"docs/cli.md has no row for `{cmd}`"


def test_version_names_the_package_and_zenoh() -> None:
    from importlib.metadata import version

    res = CliRunner().invoke(main, ["--version"])
    assert res.exit_code == 0, res.output
    assert res.output.strip().startswith(f"swarmhil {version('swarmhil')} ")
    assert f"eclipse-zenoh {version('eclipse-zenoh')}" in res.output


def test_report_bandwidth_without_a_link_is_an_empty_report(files: dict[str, Path]) -> None:
    """The demo has no [link]: the command says so, writes a page that says so, exits 0."""
    out = files["d"] / "bw.html"
    res = CliRunner().invoke(main, ["report-bandwidth", str(files["good"]), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "no inter-satellite link" in res.stdout and "DISAGREE" not in res.output
    assert "no inter-satellite link" in out.read_text() and "<img" not in out.read_text()


def test_multi_process_run_refuses_when_memory_is_short(files: dict[str, Path]) -> None:
    """1000 agent processes need about 60 GB: refused before any process starts, one line saying what
    it needs and what is available, exit code 3 (a real machine check, run as the user would)."""
    import psutil

    if psutil.virtual_memory().available > 55e9:
        pytest.skip("this machine has the memory for 1000 agents")
    out = files["d"] / "big"
    p = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "run", DEMO, "--duration", "20", "--out", str(out),
                        "--set", "dispersion.count=1000", "--set", "dispersion.require_weakly_connected=false"],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 3, p.stderr
    err = [line for line in p.stderr.splitlines() if line.strip()]
    assert len(err) == 1 and "1000 agent processes" in err[0] and "available" in err[0], p.stderr
    assert not (out / "logs").exists() and not (out / "run.json").exists()  # nothing was started


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
