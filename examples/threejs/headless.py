"""The three.js page of this folder in headless Chromium: a local web server for a site folder
holding the page and a GLB, and a screenshot of the page through Chromium's own command line
(``--screenshot`` after ``--virtual-time-budget``: the page draws once, after the GLB has loaded,
on a magenta page, so a page that did not finish shows magenta). Used by the browser test
(tests/addon/test_browser.py) and the manual's picture (screenshot.py); needs no bpy.
"""
from __future__ import annotations

import functools
import http.server
import shutil
import subprocess
import threading
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parent
PAGE = ("index.html", "main.js", "moz_lightmap.js", "node_modules")


def missing() -> list[str]:
    """What the page needs that is not installed: Debian's chromium, three.js (``npm ci``)."""
    needs = []
    if chromium() is None:
        needs.append("Debian's chromium (apt-get install chromium)")
    if not (EXAMPLE / "node_modules" / "three").is_dir():
        needs.append("three.js (cd examples/threejs && npm ci)")
    return needs


def chromium() -> str | None:
    """The path of the chromium executable, or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def make_site(folder: Path) -> Path:
    """``folder`` (created) with links to the page's files; put the GLB beside them."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in PAGE:
        (folder / name).symlink_to(EXAMPLE / name)
    return folder


def screenshot(site: Path, out: Path, size: int, query: str = "", budget_ms: int = 20000) -> Path:
    """Write ``out`` (PNG, (size + 64)² pixels, the size² canvas at the top left): Chromium's
    screenshot of ``index.html?size=<size><query>`` served from ``site`` on 127.0.0.1, after
    ``budget_ms`` of the page's virtual time."""
    handler = functools.partial(_QuietHandler, directory=str(site))
    url = "http://127.0.0.1:{}/index.html?size={}{}"
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        subprocess.run([chromium(), "--headless=new", "--no-sandbox", "--use-angle=swiftshader",
                        "--enable-unsafe-swiftshader", f"--screenshot={out.resolve()}",
                        f"--window-size={size + 64},{size + 64}",
                        f"--virtual-time-budget={budget_ms}",
                        url.format(server.server_address[1], size, query)],
                       check=True, timeout=60, capture_output=True, cwd=out.parent)
    finally:
        server.shutdown()
        server.server_close()
    return out


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    """Serves files without logging a line for each."""

    def log_message(self, format, *args):  # noqa: A002 - the base class's name
        pass
