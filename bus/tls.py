"""Per-run TLS between processes and hosts, with Zenoh's own TLS link (issue 17).

One run = one certificate authority, made fresh for the run and thrown away once it has signed:
`DIR/secrets/tls/` (mode 0700, every file 0600) holds

- `ca.pem`: the run's CA certificate (the only trust root of every session of the run);
- `router.pem` / `router.key`: the router's certificate, valid for the names and addresses the
  clients dial (`localhost`, `127.0.0.1`, `router` and any `hosts` given: the router's address on
  another host);
- `<user>.pem` / `<user>.key`: one client certificate per process (CN = its username, bus/acl.py).

The CA's private key is deleted after signing, so nobody (the launcher included) can mint another
certificate for the run. The router requires a client certificate (mutual TLS,
`transport/link/tls/enable_mtls`) on its `tls/...` endpoint; user/password authentication and the
ACL (bus/acl.py) still name the process: TLS authenticates the link and encrypts it.

Zenoh 1.10 keys (`transport/link/tls/...`): `root_ca_certificate`, `listen_certificate`,
`listen_private_key`, `connect_certificate`, `connect_private_key`, `enable_mtls`. Certificates
are made with the `openssl` command line (EC P-256, valid 7 days).
"""
from __future__ import annotations

import ipaddress
import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

from swarmhil.bus.keys import check_token

ROUTER_NAMES = ("localhost", "127.0.0.1", "router")
DAYS = "7"


class TlsError(RuntimeError):
    """The certificates could not be made (no `openssl`, or it failed)."""


def _openssl(*args: str, cwd: Path) -> None:
    exe = shutil.which("openssl")
    if exe is None:
        raise TlsError("TLS needs the `openssl` command line to make the run's certificates; install openssl")
    r = subprocess.run([exe, *args], cwd=cwd, capture_output=True, text=True, timeout=60)
    if r.returncode != 0:
        raise TlsError(f"openssl {args[0]} failed: {r.stderr.strip()[-300:]}")


def _san(names: Iterable[str]) -> str:
    out = []
    for n in dict.fromkeys(names):  # once each, in order
        try:
            ipaddress.ip_address(n)
            out.append(f"IP:{n}")
        except ValueError:
            out.append(f"DNS:{n}")
    return ",".join(out)


def _issue(d: Path, name: str, cn: str, san: str | None, server: bool) -> None:
    """A key and a certificate signed by the run's CA (d/ca.pem, d/ca.key)."""
    _openssl("req", "-new", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
             "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN={cn}", cwd=d)
    ext = ["basicConstraints=critical,CA:FALSE", "keyUsage=critical,digitalSignature",
           f"extendedKeyUsage={'serverAuth,clientAuth' if server else 'clientAuth'}"]
    if san:
        ext.append(f"subjectAltName={san}")
    (d / f"{name}.ext").write_text("\n".join(ext) + "\n")
    _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
             "-days", DAYS, "-out", f"{name}.pem", "-extfile", f"{name}.ext", cwd=d)
    for junk in (f"{name}.csr", f"{name}.ext"):
        (d / junk).unlink()


@dataclass(frozen=True)
class RunTls:
    """The TLS files of one run (see the module docstring)."""

    dir: Path

    def router_overrides(self) -> dict[str, Any]:
        return router_tls(self.dir)

    def client_overrides(self, user: str) -> dict[str, Any]:
        return client_tls(self.dir, user)


def router_tls(d: str | Path) -> dict[str, Any]:
    """The router's Zenoh settings: its certificate, and client certificates required (mTLS)."""
    d = Path(d)
    return {"transport/link/tls/root_ca_certificate": str(d / "ca.pem"),
            "transport/link/tls/listen_certificate": str(d / "router.pem"),
            "transport/link/tls/listen_private_key": str(d / "router.key"),
            "transport/link/tls/enable_mtls": True}


def client_tls(d: str | Path, user: str) -> dict[str, Any]:
    """A client's Zenoh settings: trust only the run's CA, present its own certificate."""
    d = Path(d)
    check_token(user, "process name")
    return {"transport/link/tls/root_ca_certificate": str(d / "ca.pem"),
            "transport/link/tls/connect_certificate": str(d / f"{user}.pem"),
            "transport/link/tls/connect_private_key": str(d / f"{user}.key"),
            "transport/link/tls/enable_mtls": True}


def make_run_tls(secrets_dir: Path, users: Iterable[str], hosts: Iterable[str] = ()) -> RunTls:
    """A fresh CA, the router's certificate (for ROUTER_NAMES + hosts) and one client certificate
    per user, in secrets_dir/tls (0700, files 0600); the CA key is deleted at the end."""
    d = Path(secrets_dir) / "tls"
    d.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(d, 0o700)
    old = os.umask(0o077)  # every file openssl writes is the user's only
    try:
        _openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
                 "-keyout", "ca.key", "-out", "ca.pem", "-days", DAYS, "-subj", "/CN=swarmhil run CA",
                 "-addext", "basicConstraints=critical,CA:TRUE", "-addext", "keyUsage=critical,keyCertSign", cwd=d)
        _issue(d, "router", "router", _san([*ROUTER_NAMES, *hosts]), server=True)
        for u in users:
            _issue(d, check_token(u, "process name"), u, None, server=False)
    finally:
        os.umask(old)
        for junk in ("ca.key", "ca.srl"):
            (d / junk).unlink(missing_ok=True)
    for p in d.iterdir():
        os.chmod(p, 0o600)
    return RunTls(d)
