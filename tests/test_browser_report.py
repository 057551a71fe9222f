"""The report site in a real browser (issue 18): every page renders its plots.

A 20-minute run with every kind of page (paper 002 figures, navigation from camera tracks, a link
with beacons, events) is reported with `swarmhil report`; the site is served by Python's
http.server bound to 127.0.0.1 and opened in headless Chromium (playwright-core from npm; both
installed by `make setup-system`, tests/system_tools.py, and checked before the fixture's run by
tests/conftest.py). From index.html the test follows the bar of links to every page and, on each, requires: no console error, no page error, no failed request; every Plotly
figure drawn (its div holds a `.main-svg` with plotted traces); every image loaded
(`naturalWidth > 0`). The site must load nothing from any other host (plotly.js is a file of the
site): requests elsewhere are counted and must be zero.

Run it: `.venv/bin/python -m pytest -m browser tests/test_browser_report.py`.
"""
from __future__ import annotations

import functools
import http.server
import json
import os
import subprocess
import tempfile
import threading
from pathlib import Path

import pytest

from system_tools import CACHE, CHROMIUM, require_playwright_core
from test_browser import CHROMIUM_ARGS
from test_site import site_run  # noqa: F401, F811 - the fixture: a 20-minute run with every kind of page, reported

CHECK_JS = r"""
// Open START, follow the <nav> links, and report per page what rendered and what went wrong.
const { chromium } = require(process.env.PW_CORE);
(async () => {
  const [start, udd] = process.argv.slice(2);
  const origin = new URL(start).origin;
  const ctx = await chromium.launchPersistentContext(udd, {
    executablePath: process.env.CHROMIUM, headless: true, viewport: { width: 1400, height: 1000 },
    args: JSON.parse(process.env.CHROMIUM_ARGS) });
  const page = ctx.pages()[0] || await ctx.newPage();
  let errors = [], foreign = [];
  page.on('console', m => { if (m.type() === 'error') errors.push('console: ' + m.text()); });
  page.on('pageerror', e => errors.push('pageerror: ' + e.message));
  page.on('requestfailed', r => errors.push('requestfailed: ' + r.url()));
  page.on('request', r => { if (!r.url().startsWith(origin)) foreign.push(r.url()); });
  const todo = [start], seen = new Set(), pages = [];
  while (todo.length) {
    const url = todo.shift();
    if (seen.has(url)) continue;
    seen.add(url);
    errors = []; foreign = [];
    const resp = await page.goto(url, { waitUntil: 'load', timeout: 120000 });
    // Plotly draws after load: wait until every figure div has its SVG (or give up after 60 s)
    await page.waitForFunction(() => [...document.querySelectorAll('.plotly-graph-div')]
        .every(d => d.querySelector('.main-svg')), null, { timeout: 60000 }).catch(() => {});
    const info = await page.evaluate(() => ({
      title: document.title,
      plots: [...document.querySelectorAll('.plotly-graph-div')].map(d => ({
        id: d.id, svg: d.querySelectorAll('.main-svg').length,
        traces: d.querySelectorAll('.scatterlayer .trace').length,
        paths: [...d.querySelectorAll('.scatterlayer path.js-line, .scatterlayer path.point')]
                 .filter(p => (p.getAttribute('d') || '').length > 10).length,
        width: d.getBoundingClientRect().width, height: d.getBoundingClientRect().height })),
      images: [...document.images].map(i => ({ src: i.getAttribute('src'), complete: i.complete,
                                              w: i.naturalWidth, h: i.naturalHeight })),
      links: [...document.querySelectorAll('nav a')].map(a => a.href),
    }));
    pages.push({ url, status: resp ? resp.status() : 0, errors, foreign, ...info });
    for (const l of info.links) if (!seen.has(l)) todo.push(l);
  }
  console.log(JSON.stringify(pages));
  await ctx.close();
})().catch(e => { console.error(e); process.exit(1); });
"""


def check_site(site: Path) -> list[dict]:
    """Serve site on 127.0.0.1 and visit every page linked from index.html in headless Chromium."""
    mod = require_playwright_core()
    script = CACHE / "check_site.js"
    script.write_text(CHECK_JS)
    handler = functools.partial(_QuietHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    th = threading.Thread(target=server.serve_forever, daemon=True)
    th.start()
    try:
        with tempfile.TemporaryDirectory(prefix="swarmhil-chromium-") as udd:
            env = dict(os.environ, PW_CORE=str(mod), CHROMIUM=CHROMIUM, CHROMIUM_ARGS=json.dumps(CHROMIUM_ARGS))
            url = f"http://127.0.0.1:{server.server_address[1]}/index.html"
            res = subprocess.run(["node", str(script), url, udd], env=env, capture_output=True, text=True, timeout=600)
    finally:
        server.shutdown()
        server.server_close()
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args: object) -> None:
        pass


@pytest.mark.system
@pytest.mark.browser
@pytest.mark.timeout(1800)  # the fixture's run (20 simulated minutes) and report, then up to 600 s in the browser
def test_every_page_of_the_report_site_renders_in_chromium(site_run: Path) -> None:  # noqa: F811
    pages = check_site(site_run / "report")
    names = sorted(Path(p["url"]).name for p in pages)
    # every page of the site is reachable from the index, and this run has every kind of page
    assert names == ["bandwidth.html", "data.html", "events.html", "index.html", "navigation.html"], names
    n_plots = n_images = 0
    for p in pages:
        where = Path(p["url"]).name
        assert p["status"] == 200, where
        assert p["errors"] == [], (where, p["errors"])
        assert p["foreign"] == [], (where, p["foreign"])  # nothing from a CDN or any other host
        for d in p["plots"]:
            assert d["svg"] >= 1 and d["traces"] >= 1 and d["paths"] >= 1, (where, d)
            assert d["width"] > 300 and d["height"] > 200, (where, d)
        for i in p["images"]:
            assert i["complete"] and i["w"] > 0 and i["h"] > 0, (where, i)
        n_plots += len(p["plots"])
        n_images += len(p["images"])
    by = {Path(p["url"]).name: p for p in pages}
    assert len(by["index.html"]["plots"]) >= 10  # the many-line figures of paper 002 are interactive
    assert len(by["navigation.html"]["images"]) >= 4
    # bandwidth: the per-agent traffic interactive, the rate, link matrix and drops as images
    assert len(by["bandwidth.html"]["plots"]) == 1 and len(by["bandwidth.html"]["images"]) == 3
    print(f"{len(pages)} pages, {n_plots} Plotly figures, {n_images} images rendered")
