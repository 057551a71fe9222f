"""Viewer options of `swarmhil run` and the `swarmhil replay` command (docs/viewer.md)."""
from __future__ import annotations

import functools
import json
import sys
from pathlib import Path
from typing import Any, Callable

import click

VIZ_MODES = ("none", "save", "serve", "connect", "foxglove")
FOXGLOVE_LAYOUT = "dashboards/foxglove/swarmhil-layout.json"


def _check_viz(_ctx: click.Context, _param: click.Parameter, value: str) -> str:
    if value in VIZ_MODES or value.startswith(("rerun://", "rerun+http://", "rerun+https://")):
        return value
    raise click.BadParameter(f"{value!r}: use one of {', '.join(VIZ_MODES)} or a rerun+http://HOST:PORT/proxy URL")


def viz_option(f: Callable[..., Any]) -> Callable[..., Any]:
    """--viz MODE|URL, --viz-url, --viz-port, --web-port on a click command."""
    opts = [
        click.option("--viz", default="none", show_default=True, callback=_check_viz,
                     metavar="save|serve|connect|foxglove|none|URL",
                     help="Viewer bridge: save RUN_DIR/run.rrd; serve it live on 127.0.0.1 (web viewer, until Ctrl-C); "
                          "connect to a running viewer (--viz-url, or give the URL itself); foxglove: a Foxglove "
                          "WebSocket server on 127.0.0.1 during the run."),
        click.option("--viz-url", help="gRPC URL for --viz connect (default rerun+http://127.0.0.1:9876/proxy)."),
        click.option("--viz-port", type=click.IntRange(0, 65535),
                     help="--viz serve: gRPC port on 127.0.0.1 (default: a free one); --viz foxglove: WebSocket port "
                          "(default 8765, 0: a free one)."),
        click.option("--web-port", type=int, help="--viz serve: web viewer port on 127.0.0.1 (default: a free one)."),
    ]
    return functools.reduce(lambda acc, opt: opt(acc), reversed(opts), f)


def viz_opts(*, in_process: bool = False, viz: str = "none", viz_url: str | None = None, viz_port: int | None = None,
             web_port: int | None = None) -> dict[str, Any]:
    """Companion options for the launcher; in serve mode picks the ports now and prints the URL."""
    if viz.startswith("rerun"):
        viz, viz_url = "connect", viz
    if viz == "none":
        return {}
    from swarmhil.bus.optional import require  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    # before the run starts, not in its viewer process
    require("foxglove" if viz == "foxglove" else "rerun", f"--viz {viz}")
    opts: dict[str, Any] = {"viz": viz}
    if viz == "connect":
        opts["viz_url"] = viz_url or "rerun+http://127.0.0.1:9876/proxy"
    if viz == "foxglove":
        opts["viz_port"] = _free_or_exit(8765 if viz_port is None else viz_port)
        click.echo(f"foxglove: ws://127.0.0.1:{opts['viz_port']}  (Foxglove: Open connection -> Foxglove WebSocket; "
                   f"layout {FOXGLOVE_LAYOUT})", err=True)
    if viz == "serve":
        from swarmhil.dashboards.viz_node import disable_analytics, free_port, web_url  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        disable_analytics()
        opts["viz_port"] = viz_port or free_port()
        opts["web_port"] = web_port or free_port()
        opts["viz_hold"] = in_process
        click.echo(f"viewer: {web_url(opts['web_port'], opts['viz_port'])}", err=True)
        click.echo(f"  from another machine: ssh -N -L {opts['web_port']}:127.0.0.1:{opts['web_port']} "
                   f"-L {opts['viz_port']}:127.0.0.1:{opts['viz_port']} USER@THIS_HOST, then open the same URL there",
                   err=True)
    return opts


def _free_or_exit(port: int) -> int:
    """The port itself when 127.0.0.1:port can be bound now (0: a free one), else one line and exit 2."""
    import socket

    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError as exc:
            raise click.BadParameter(f"127.0.0.1:{port} cannot be bound ({exc.strerror or exc}); give another --viz-port",
                                     param_hint="--viz-port") from None
        return int(s.getsockname()[1])


@click.command()
@click.argument("mcap_path", metavar="RUN_DIR/run.mcap", type=click.Path(exists=True, dir_okay=False))
@click.option("--rrd", "rrd_out", type=click.Path(dir_okay=False), help="Write the views to this .rrd "
              "(default RUN_DIR/replay.rrd unless --serve).")
@click.option("--serve", is_flag=True, help="Serve the views in the web viewer on 127.0.0.1 until Ctrl-C.")
@click.option("--viz-port", type=int, help="--serve: gRPC port on 127.0.0.1 (default: a free one).")
@click.option("--web-port", type=int, help="--serve: web viewer port on 127.0.0.1 (default: a free one).")
def replay(mcap_path: str, rrd_out: str | None, serve: bool, viz_port: int | None, web_port: int | None) -> None:
    """Build the viewer's views from a recording alone: RUN_DIR/run.mcap -> .rrd and/or web viewer."""
    from swarmhil.dashboards.replay import ReplayError  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.dashboards.replay import replay as do_replay  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.bus.optional import require  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.cli_inputs import check_recording  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    require("rerun", "swarmhil replay")
    check_recording(mcap_path)

    if rrd_out is None and not serve:
        rrd_out = str(Path(mcap_path).with_name("replay.rrd"))

    def show(url: str) -> None:
        click.echo(f"viewer: {url}  (Ctrl-C to stop)", err=True)

    try:
        stats = do_replay(mcap_path, rrd_out, serve=serve, viz_port=viz_port, web_port=web_port, on_url=show)
    except ReplayError as exc:
        raise click.ClickException(str(exc)) from None
    if rrd_out:
        click.echo(f"wrote {rrd_out}")
    click.echo(json.dumps({k: stats[k] for k in ("samples", "last_step", "rejected")}), file=sys.stdout)
