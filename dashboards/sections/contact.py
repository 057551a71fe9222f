"""Report section `contact` (issue 27): contacts between hulls and near misses of the keep-out
distance, read from the recording's `event` topic (plant/contact.py), and the overview's flag."""
from __future__ import annotations

from typing import Any

from swarmhil.dashboards.sections import SectionContext, SectionResult, register_section
from swarmhil.dashboards.sections.faults import read_events, table


@register_section("contact", applies=lambda cfg: True)
def contact(ctx: SectionContext) -> SectionResult:
    cfg = ctx.config.get("contact") or {}
    point = bool(cfg.get("point_masses"))
    out: dict[str, Any] = {"point_masses": point, "keep_out_m": cfg.get("keep_out_m"),
                           "default_radius_m": cfg.get("default_radius_m")}
    events = read_events(ctx.mcap, "event", ("contact", "near_miss"))
    rows = []
    for kind in ("contact", "near_miss"):
        ev = [e for e in events if e.kind == kind]
        out[f"{kind}_count"] = len(ev)
        out[f"first_{kind}"] = {"t_s": ev[0].header.t, "pair": ev[0].subject.split("|")} if ev else None
        rows += [[kind, f"{e.header.t:.6g}", e.subject.replace("|", " - "), e.detail] for e in ev[:50]]
    if not cfg:
        intro = "<p>The recording predates hulls (issue 27): contacts were not looked for.</p>"
    elif point:
        intro = "<p>The scenario declares its spacecraft and bodies point masses (<code>[contact] point_masses</code>): " \
                "contacts are not looked for, only the keep-out distance between centres.</p>"
    else:
        intro = (f"<p>Hulls: spheres of <code>radius_m</code> (default {cfg.get('default_radius_m')} m) and the bodies' "
                 f"shapes; keep-out distance {cfg.get('keep_out_m')} m (0: not watched). The first 50 events:</p>")
    return SectionResult("Contacts and near misses", out, [], intro + (table(["event", "t [s]", "pair", "detail"], rows)
                                                                      if rows else "<p>None.</p>"))


def overview_rows(summary: dict[str, Any]) -> list[tuple[str, str]]:
    """The overview's flag: contacts and near misses (count, first time, pair), or the point masses."""
    m = (summary.get("metrics") or {}).get("contact")
    if not m:
        return []
    if m.get("point_masses"):
        contacts = "not looked for: the scenario declares point masses"
    else:
        contacts = _flag(m["contact_count"], m["first_contact"])
    rows = [("CONTACTS between hulls" if m.get("contact_count") else "contacts between hulls", contacts)]
    if m.get("keep_out_m"):
        rows.append((f"near misses (< {m['keep_out_m']:g} m keep-out)", _flag(m["near_miss_count"], m["first_near_miss"])))
    return rows


def _flag(count: int, first: dict[str, Any] | None) -> str:
    if not count or first is None:
        return "none"
    return f"{count}, first at t = {first['t_s']:.6g} s: {' - '.join(first['pair'])}"
