"""The `swarmhil` command line."""
from __future__ import annotations

import json
import logging
import os
import sys
from pathlib import Path
from typing import Any

import click

from swarmhil.bus.optional import MissingExtra
from swarmhil.deploy.cli_viz import viz_option
from swarmhil.deploy.mesh import scenario_placement
from swarmhil.deploy.netns import NetnsError, check_netns_possible


def _bad_file_errors() -> tuple[type[BaseException], ...]:
    import struct

    from google.protobuf.message import DecodeError
    from mcap.exceptions import McapError

    return (McapError, struct.error, EOFError, DecodeError, UnicodeDecodeError, json.JSONDecodeError, OSError)


EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_MEMORY, EXIT_INTERNAL = 0, 1, 2, 3, 70  # docs/cli.md "Exit codes"
EXIT_DIVERGED = 5  # `refly --exit-code`: the re-flown commands differ from the recorded ones
_VERBOSE = 0


def _fail(msg: str, code: int) -> None:
    click.echo(f"error: {' '.join(msg.split())}", err=True)
    sys.exit(code)


class _Cli(click.Group):
    """Every command: a file that is not what it should be (garbage, a truncated recording, a
    directory that cannot be written) ends in one line naming it and exit code 1, a bad option or
    argument in one line and exit code 2, never a traceback (docs/cli.md)."""

    def invoke(self, ctx: click.Context) -> Any:
        args = [*getattr(ctx, "_protected_args", []), *ctx.args]  # invoke() empties them
        try:
            return super().invoke(ctx)
        except BrokenPipeError:  # `swarmhil mcap info F | head`: the reader left, not a bad file
            raise
        except _bad_file_errors() as exc:  # (recordings and run directories are checked up front: cli_inputs.py)
            files = [a for a in args if Path(a).exists()]
            what = f"{', '.join(files)}: " if files else ""
            detail = " ".join(f"{type(exc).__name__}: {exc}".split())
            hint = "; a recording whose writer was killed: `swarmhil mcap repair`" if "mcap" in type(exc).__module__ else ""
            raise click.ClickException(f"{what}cannot read or write this ({detail[:300]}){hint}") from None

    def main(self, args: Any = None, prog_name: str | None = None, complete_var: str | None = None,
             standalone_mode: bool = True, **extra: Any) -> Any:
        """click's main, with every error on one line: `error: ...` and the exit code of docs/cli.md."""
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, False, **extra)
        try:
            rv = super().main(args, prog_name, complete_var, False, **extra)
        except click.UsageError as exc:  # bad option, missing argument, path that does not exist: 2
            if type(exc).__name__ == "NoArgsIsHelpError" and exc.ctx is not None:  # `swarmhil`, `swarmhil mcap`
                click.echo(exc.ctx.get_help(), err=True)
                sys.exit(exc.exit_code)
            hint = f" (see `{exc.ctx.command_path} --help`)" if exc.ctx is not None else ""
            _fail(exc.format_message() + hint, exc.exit_code)
        except click.ClickException as exc:  # a file that cannot be read or written: 1
            _fail(exc.format_message(), exc.exit_code)
        except MissingExtra as exc:  # an optional part not installed (bus/optional.py): 1
            _fail(str(exc), EXIT_FAILED)
        except BrokenPipeError:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
            sys.exit(EXIT_OK)
        except click.Abort:
            click.echo("aborted", err=True)
            sys.exit(EXIT_FAILED)
        except Exception as exc:  # noqa: BLE001 - a bug, not bad input: one line; -v shows the traceback
            if _VERBOSE:
                raise
            _fail(f"internal error: {type(exc).__name__}: {exc} (a bug: `swarmhil -v ...` shows the traceback)"[:600],
                  EXIT_INTERNAL)
        sys.exit(rv if isinstance(rv, int) else EXIT_OK)


def _print_version(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    """--version: this package's version (package metadata) and the Zenoh it runs on."""
    if not value or ctx.resilient_parsing:
        return
    from importlib.metadata import PackageNotFoundError, version

    def ver(dist: str) -> str:
        try:
            return version(dist)
        except PackageNotFoundError:
            return "not installed"
    click.echo(f"swarmhil {ver('swarmhil')} (eclipse-zenoh {ver('eclipse-zenoh')}, Python {sys.version.split()[0]})")
    ctx.exit(0)


def _clear_run(out: Path) -> None:
    """Remove what a previous run wrote in `out` (only the run's own files)."""
    import shutil

    for name in ("run.mcap", "run.json", "summary.json", "scenario.json", "run.rrd", "viewer_url.txt"):
        (out / name).unlink(missing_ok=True)
    for p in out.glob("*_summary.json"):
        p.unlink()
    for d in ("agents", "logs", "secrets", "external"):
        shutil.rmtree(out / d, ignore_errors=True)


@click.group(cls=_Cli, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug); tracebacks of internal errors.")
@click.option("--version", is_flag=True, expose_value=False, is_eager=True, callback=_print_version,
              help="Print the versions of swarmhil and Zenoh and exit.")
def main(verbose: int) -> None:
    """swarmhil: spacecraft-swarm flight software as processes over Eclipse Zenoh."""
    global _VERBOSE
    _VERBOSE = verbose
    logging.basicConfig(level=[logging.WARNING, logging.INFO, logging.DEBUG][min(verbose, 2)],
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")


@main.command()
@click.argument("scenario", type=click.Path(dir_okay=False))
@click.option("--out", "out", type=click.Path(file_okay=False), help="Output directory (default runs/<run id>).")
@click.option("--duration", type=float, help="Simulated seconds (overrides [run].duration_s).")
@click.option("--seed", type=int, help="Seed of the dispersion and noise generators.")
@click.option("--mode", type=click.Choice(["lockstep", "realtime"]), help="Time mode (default: the scenario's).")
@click.option("--speed", type=float, help="Real-time factor in realtime mode.")
@click.option("--in-process", is_flag=True, help="Plant, agents and recorder in one process over the in-memory bus.")
@click.option("--record", type=click.Choice(["all", "truth"]), default="all", show_default=True,
              help="In-process runs: all: every message; truth: the truth and events only. Either way the flight "
                   "software of all spacecraft runs as one batch where the scenario allows (the same messages and "
                   "truth, several times faster; summary.json batch.why_not says why not).")
@click.option("--run-id", help="Run id (the <run> of swarm/<run>/**); default <scenario>-<time>-<hex>.")
@click.option("--no-progress", is_flag=True, help="No progress bar.")
@click.option("--overwrite", is_flag=True, help="Replace the run already in --out (refused otherwise).")
@click.option("--insecure", is_flag=True,
              help="Multi-process runs: no per-process credentials and access control on the router (docs/reliability.md).")
@click.option("--tls", is_flag=True,
              help="Multi-process runs: mutual TLS to the router with per-run certificates in DIR/secrets/tls (needs openssl).")
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE",
              help="Override any scenario field (repeatable; value parsed as TOML), validated like the file.")
@click.option("--join-listen", metavar="ENDPOINT",
              help="Multi-process runs with external flight software: the router also listens here (an address of "
                   "another network, e.g. tls/10.0.0.1:7447) and the join kits point here (docs/hil.md).")
@click.option("--hosts", type=click.IntRange(min=1), default=1, show_default=True, metavar="K",
              help="Multi-process runs: spread the run over K hosts, one Zenoh router each, the routers linked as a "
                   "mesh; agents round-robin over the hosts or on their [[spacecraft]] host; plant, clock and "
                   "recorder on host 0 (docs/scaling.md).")
@click.option("--netns", is_flag=True,
              help="With --hosts K: hosts 1..K-1 each a network namespace with its own address, all on one bridge "
                   "with the launcher's host, made and removed by the run (needs root and iproute2).")
@viz_option
def run(scenario: str, out: str | None, duration: float | None, seed: int | None, mode: str | None,
        speed: float | None, in_process: bool, record: str, run_id: str | None, no_progress: bool, overwrite: bool,
        insecure: bool, tls: bool, sets: tuple[str, ...], join_listen: str | None, hosts: int, netns: bool,
        **viz: Any) -> None:
    """Run SCENARIO.toml: writes DIR/run.mcap and DIR/summary.json."""
    from swarmhil.deploy.cli_viz import viz_opts  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.launcher import MultiProcessRun, new_run_id, run_in_process  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.scenario import ScenarioError, load_scenario  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if record != "all" and not in_process:
        click.echo("error: --record truth needs --in-process (multi-process runs record every message)", err=True)
        sys.exit(2)
    try:
        sc = load_scenario(scenario, sets).with_overrides(duration_s=duration, seed=seed, mode=mode, speed=speed)
    except ScenarioError as exc:  # one line naming the field, exit code 2 (usage error), no traceback
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    from swarmhil.bus.keys import check_token  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if in_process:
        from swarmhil.deploy.external import external_ids  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        if external_ids(sc):
            click.echo(f"error: {scenario}: {', '.join(external_ids(sc))} fly external flight software "
                       "(fsw = \"external\"); that needs a multi-process run: drop --in-process", err=True)
            sys.exit(2)
    if hosts > 1 and in_process:
        click.echo("error: --hosts needs a multi-process run: drop --in-process", err=True)
        sys.exit(2)
    if netns and hosts < 2:
        click.echo("error: --netns needs --hosts 2 or more (host 0 is this namespace)", err=True)
        sys.exit(2)
    if netns:
        try:
            check_netns_possible()
        except NetnsError as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(2)
    if not in_process:
        try:
            scenario_placement(sc, hosts)
        except ValueError as exc:
            click.echo(f"error: {scenario}: {exc}", err=True)
            sys.exit(2)
    if tls and (insecure or in_process):
        click.echo(f"error: --tls cannot be combined with {'--insecure' if insecure else '--in-process'}", err=True)
        sys.exit(2)
    if insecure and sc.tls and not in_process:
        click.echo(f"error: --insecure conflicts with [security].tls = true of {scenario} "
                   "(TLS names each process by its credential); add --set security.tls=false", err=True)
        sys.exit(2)
    try:
        rid = check_token(run_id, "--run-id") if run_id is not None else new_run_id(sc.name)
    except ValueError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    out_dir = Path(out) if out else Path("runs") / rid
    if any((out_dir / f).exists() for f in ("run.mcap", "summary.json", "run.json")):
        if not overwrite:
            click.echo(f"error: --out {out_dir} already holds a run; give another directory or --overwrite", err=True)
            sys.exit(2)
        _clear_run(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        probe = out_dir / ".swarmhil-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        click.echo(f"error: --out {out_dir}: cannot write there ({exc.strerror or exc})", err=True)
        sys.exit(2)
    progress = not no_progress and sys.stderr.isatty()
    opts = viz_opts(in_process=in_process, **viz)
    if insecure:
        opts["secure"] = False
    if tls:
        opts["tls"] = True
    if hosts > 1:
        opts["hosts"] = hosts
    if netns:
        opts["netns"] = True
    if join_listen:
        from swarmhil.deploy.external import check_join_listen  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        try:
            check_join_listen(join_listen, bool(opts.get("tls", sc.tls)), sc)
        except ValueError as exc:
            _fail(str(exc), EXIT_USAGE)
        opts["join_listen"] = join_listen
    if in_process:
        res = run_in_process(sc, out_dir, rid, progress=progress, opts=opts, record=record)
    else:
        from swarmhil.deploy.launcher import RunFailed  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
        from swarmhil.deploy.memory import NotEnoughMemory  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
        from swarmhil.bus.tls import TlsError  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        try:
            res = MultiProcessRun(scenario, sc, out_dir, rid, progress=progress, opts=opts,
                                  overrides={"duration": duration, "seed": seed, "mode": mode, "speed": speed}).execute()
        except RunFailed as exc:  # the run could not start (its router)
            click.echo(f"error: {' '.join(str(exc).split())[:400]}", err=True)
            sys.exit(1)
        except NotEnoughMemory as exc:
            _fail(str(exc), EXIT_MEMORY)
        except TlsError as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(1)
    s = res.summary
    if s.get("external_join_timeout"):  # one line: which spacecraft, which endpoint (deploy/external.py)
        _fail(res.reason, EXIT_FAILED)
    click.echo(f"run {s['run']}: {s.get('steps', 0)} steps of {s['step_s']} s, {s['agents']} agents, "
               f"wall {s['wall_s']:.1f} s, total dV {s['delta_v_total_mps']:.4f} m/s, "
               f"dead {sorted(s['dead_agents'])}, rejected packets {s['rejected_packets']}")
    click.echo(f"wrote {out_dir / 'run.mcap'} and {out_dir / 'summary.json'}")
    if res.exit_code:
        click.echo(f"run failed: {res.reason}", err=True)
        sys.exit(res.exit_code)


@main.command()
@click.option("--listen", required=True, metavar="ENDPOINT", help="Endpoint to listen on, e.g. tcp/127.0.0.1:7447.")
@click.option("--acl-dir", type=click.Path(file_okay=False), help="A run's secrets directory (users.txt, acl.json).")
def router(listen: str, acl_dir: str | None) -> None:
    """The run's Zenoh router as its own process (what `swarmhil run` starts; compose and multi-host
    deployments too). Runs until SIGTERM or Ctrl-C."""
    from swarmhil.deploy.router import main as router_main  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    sys.exit(router_main(["--listen", listen, *(["--acl-dir", acl_dir] if acl_dir else [])]))


@main.group()
def mcap() -> None:
    """MCAP recording tools."""


@mcap.command("repair")
@click.argument("src", type=click.Path(exists=True, dir_okay=False))
@click.argument("dst", type=click.Path(dir_okay=False))
def mcap_repair(src: str, dst: str) -> None:
    """Salvage every complete chunk of a recording whose writer was killed into DST."""
    from swarmhil.bus.mcap_tools import repair  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.cli_inputs import recording_problem  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    problem = recording_problem(src)
    if problem and not problem.startswith("is cut short"):
        raise click.ClickException(f"{src}: {problem}; nothing to repair")
    stats = repair(src, dst)
    click.echo(json.dumps(stats))
    if not stats["messages"]:
        raise click.ClickException(f"{src}: no complete message could be salvaged")


@mcap.command("merge")
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False))
def mcap_merge(files: tuple[str, ...]) -> None:
    """Join the segments of one run (SEG... OUT: run.mcap run.001.mcap ... merged.mcap) into OUT,
    the segments of a recorder that was killed and restarted; a segment without footer is read as
    `repair` reads it. The metadata `swarmhil.segments` keeps each segment's span (the gaps)."""
    from swarmhil.bus.mcap_tools import merge  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if len(files) < 2:
        raise click.ClickException("give one or more segments and the output file: mcap merge SEG... OUT")
    *segs, dst = files
    for src in segs:
        with open(src, "rb") as f:
            if f.read(8) != b"\x89MCAP0\r\n":
                raise click.ClickException(f"{src}: not an MCAP recording (no MCAP magic at the start)")
    if Path(dst).resolve() in {Path(x).resolve() for x in segs}:
        raise click.ClickException(f"{dst}: the output is one of the segments")
    stats = merge(list(segs), dst)
    click.echo(json.dumps(stats))
    if not stats["messages"]:
        raise click.ClickException("no complete message could be read from the segments")


@mcap.command("info")
@click.argument("src", type=click.Path(exists=True, dir_okay=False))
def mcap_info(src: str) -> None:
    """Message counts per topic of a recording."""
    from swarmhil.bus.mcap_tools import topic_counts  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.cli_inputs import check_recording  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    check_recording(src)
    for topic, n in sorted(topic_counts(src).items()):
        click.echo(f"{n:8d}  {topic}")


@main.command()
@click.argument("scenario", type=click.Path(exists=True, dir_okay=False))
@click.option("--out", "out", type=click.Path(), default=None,
              help="The compose file to write (default compose.yml); with --hosts, a new directory (one project per host).")
@click.option("--run-id", help="Run id; default <scenario>-<time>-<hex>.")
@click.option("--image", default="swarmhil:latest", show_default=True)
@click.option("--router-host", "router_hosts", multiple=True, metavar="ADDRESS",
              help="The router's address as other hosts dial it (repeatable): named in its TLS certificate.")
@click.option("--hosts", "hosts_spec", metavar="NAME[=ADDRESS[:PORT]],...",
              help="One project per host, each with its own router, the routers a mesh (each dials the others at "
                   "ADDRESS, default the NAME; port 7447); agents round-robin or on their [[spacecraft]] host "
                   "(counted from 0 in this order); plant, clock, recorder on the first host.")
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE",
              help="Override any scenario field (repeatable; value parsed as TOML), validated like the file (as `run --set`).")
def compose(scenario: str, out: str | None, run_id: str | None, image: str, router_hosts: tuple[str, ...],
            hosts_spec: str | None, sets: tuple[str, ...]) -> None:
    """Write a compose project (compose.yml, scenario.json, secrets/) that starts the run's processes as
    containers, each agent its own, on mutual TLS with per-run credentials (docs/reliability.md); with
    --hosts, one project per host whose routers form a mesh (docs/scaling.md)."""
    from swarmhil.deploy.compose import parse_hosts, write_compose, write_compose_hosts  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.launcher import new_run_id  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.scenario import ScenarioError, load_scenario  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    hosts = None
    if hosts_spec is not None:
        if router_hosts:
            _fail("--router-host and --hosts: with --hosts the routers' addresses are the hosts' (NAME=ADDRESS)", EXIT_USAGE)
        if out is None or Path(out).suffix in (".yml", ".yaml"):
            _fail(f"--hosts writes one project per host under a directory: give --out DIR"
                  f"{f' (not the file {out})' if out else ''}", EXIT_USAGE)
        try:
            hosts = parse_hosts(hosts_spec)
        except ValueError as exc:
            _fail(str(exc), EXIT_USAGE)
    try:
        sc = load_scenario(scenario, sets)
    except ScenarioError as exc:
        _fail(str(exc), EXIT_USAGE)
    from swarmhil.deploy.external import external_ids  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if external_ids(sc):  # a compose project starts every agent; external flight software joins a `swarmhil run`
        _fail(f"{scenario}: {', '.join(external_ids(sc))} fly external flight software (fsw = \"external\"), which a "
              "compose project does not start: use `swarmhil run` (docs/hil.md)", EXIT_USAGE)
    from swarmhil.bus.keys import check_token  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.bus.tls import TlsError  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    try:
        rid = check_token(run_id, "--run-id") if run_id is not None else new_run_id(sc.name)
        addresses = [check_token(h, "--router-host") for h in router_hosts]
    except ValueError as exc:
        _fail(str(exc), EXIT_USAGE)
    if hosts is not None:
        try:
            placed = write_compose_hosts(sc, scenario, rid, Path(out), hosts, image=image)
        except ValueError as exc:  # a [[spacecraft]] host beyond the hosts, a DIR not empty: nothing written
            _fail(str(exc), EXIT_USAGE)
        except (OSError, TlsError) as exc:
            _fail(str(exc), EXIT_FAILED)
        for h in placed["hosts"]:
            click.echo(f"wrote {Path(out) / h['project']} (host {h['host']}, router {h['router']}, {len(h['agents'])} agents"
                       f"{', ' + ', '.join(h['ground']) if h['ground'] else ''})")
        click.echo(f"wrote {Path(out) / 'placement.json'}")
        return
    if Path(out or "compose.yml").is_dir():
        _fail(f"--out {out}: a directory; give the compose file to write (a directory is for --hosts)", EXIT_USAGE)
    try:
        path = write_compose(sc, scenario, rid, Path(out or "compose.yml"), image=image, router_hosts=addresses)
    except (OSError, TlsError) as exc:
        _fail(str(exc), EXIT_FAILED)
    click.echo(f"wrote {path} ({len(sc.ids)} agents)")


@main.command()
@click.option("--out", "out", type=click.Path(file_okay=False), default="runs/demo", show_default=True,
              help="Output directory (replaced if it holds an earlier demo).")
@click.option("--in-process", is_flag=True, help="Run in one process (default: one process per spacecraft).")
@click.pass_context
def demo(ctx: click.Context, out: str, in_process: bool) -> None:
    """The first five minutes: run the demo scenario (6 spacecraft, 30 simulated minutes) with its 3D
    views saved, write its report, and print where both are and the one command that opens each."""
    from swarmhil.bus.optional import require  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    require("rerun", "swarmhil demo (its 3D views)")  # before the run, not after it
    require("matplotlib", "swarmhil demo (its report)")
    scenario = Path(__file__).resolve().parent / "scenarios" / "demo.toml"
    ctx.invoke(run, scenario=str(scenario), out=out, overwrite=True, viz="save", in_process=in_process)
    ctx.invoke(_report_cmd, run_dir=out)
    out_dir = Path(out).resolve()
    rrd, page = out_dir / "run.rrd", out_dir / "report" / "index.html"
    for f in (rrd, page):
        if not f.is_file():
            raise click.ClickException(f"{f}: the demo did not write it")
    viewer = Path(sys.executable).with_name("rerun")
    click.echo("")
    click.echo(f"the swarm in 3D (Rerun):  {rrd}")
    click.echo(f"  open it with:           {viewer if viewer.exists() else 'rerun'} {rrd}")
    click.echo(f"its report (figures):     {page}")
    click.echo(f"  open it with:           python3 -m webbrowser {page.as_uri()}")


@main.command()
@click.argument("run_path", metavar="RUN", type=click.Path(exists=True, file_okay=False))
@click.option("--agent", "sid", required=True, metavar="ID", help="The spacecraft whose flight software is re-flown.")
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE",
              help="Change the scenario before building the agent, as `run --set` (e.g. a gain); repeatable.")
@click.option("--until", "until_s", type=float, metavar="SECONDS", help="Stop after this simulated time.")
@click.option("--out", "out", type=click.Path(file_okay=False),
              help="Where the difference table and figure go (default RUN/refly-<ID>).")
@click.option("--exit-code", is_flag=True, help="Exit 5 when the re-flown commands differ from the recorded ones.")
def refly(run_path: str, sid: str, sets: tuple[str, ...], until_s: float | None, out: str | None,
          exit_code: bool) -> None:
    """Re-fly one agent of the run in directory RUN alone on its recorded stimuli and link deliveries; compare
    every command with the recorded one and print the first divergence (docs/hil.md)."""
    from swarmhil.deploy.refly import ReflyConfigError, ReflyError, agent_config_of, read_recorded, refly as refly_agent, write_outputs  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.cli_inputs import check_run_dir  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.scenario import ScenarioError  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    check_run_dir(run_path)
    try:
        rec = read_recorded(run_path, sid)
    except ReflyError as exc:  # not a recording of this agent's inputs: 1
        _fail(str(exc), EXIT_FAILED)
    try:
        res = refly_agent(rec, agent_config_of(rec, sets), until_s)
    except (ScenarioError, ReflyConfigError) as exc:  # a --set the scenario or the controller refuses: 2
        _fail(str(exc), EXIT_USAGE)
    out_dir = Path(out) if out else Path(run_path) / f"refly-{sid}"
    files = write_outputs(res, out_dir)
    click.echo(res.verdict())
    click.echo(f"re-flown in {res.wall_s:.1f} s wall ({res.steps / max(res.wall_s, 1e-9):.0f} steps/s); "
               f"wrote {', '.join(str(f) for f in files)}")
    if exit_code and res.diffs:
        sys.exit(EXIT_DIVERGED)


from swarmhil.deploy.cli_report import report as _report_cmd; main.add_command(_report_cmd)  # noqa: E402,E702
from swarmhil.deploy.cli_report import sweep as _sweep_cmd; main.add_command(_sweep_cmd)  # noqa: E402,E702
from swarmhil.deploy.cli_viz import replay as _replay_cmd; main.add_command(_replay_cmd)  # noqa: E402,E702
from swarmhil.deploy.cli_bandwidth import report_bandwidth as _bandwidth_cmd; main.add_command(_bandwidth_cmd)  # noqa: E402,E702
from swarmhil.deploy.cli_nav import report_nav as _report_nav_cmd; main.add_command(_report_nav_cmd)  # noqa: E402,E702
from swarmhil.deploy.cli_campaign import campaign as _campaign_cmd; main.add_command(_campaign_cmd)  # noqa: E402,E702
from swarmhil.deploy.cli_campaign import campaign_compare as _campaign_compare_cmd; main.add_command(_campaign_compare_cmd)  # noqa: E402,E702
from swarmhil.claims.cli import claims as _claims_cmd; main.add_command(_claims_cmd)  # noqa: E402,E702
from swarmhil.deploy.cli_image import image as _image_cmd; main.add_command(_image_cmd)  # noqa: E402,E702
from swarmhil.deploy.cli_scale import scale as _scale_cmd; main.add_command(_scale_cmd)  # noqa: E402,E702


if __name__ == "__main__":
    main()
