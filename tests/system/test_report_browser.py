"""The HTML report in a real browser: every image decodes and every table cell is filled.

Renders ``report.html`` of a tiny ``reproduce all`` in headless Chromium (Debian's ``chromium``,
or ``$STOCHPEND_BROWSER``) from a copy with a small script appended that writes its checks into
the DOM; ``--dump-dom`` returns the DOM after the load event. Skipped, with the reason, when no
browser is found.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess

import pytest

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome")

CHECK_SCRIPT = """
<script>
window.addEventListener("load", function () {
  var imgs = Array.prototype.slice.call(document.images);
  var bad = imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0); })
                .map(function (i) { return i.alt; });
  var cells = Array.prototype.slice.call(document.querySelectorAll("table td, table th"));
  var empty = cells.filter(function (c) { return c.textContent.trim() === ""; })
                   .map(function (c) { return c.parentNode.textContent.slice(0, 80); });
  var out = document.createElement("pre");
  out.id = "stochpend-checks";
  out.textContent = JSON.stringify({
    images: imgs.length, bad_images: bad,
    widths: imgs.map(function (i) { return i.naturalWidth; }),
    tables: document.querySelectorAll("table").length, cells: cells.length, empty_cells: empty
  });
  document.body.appendChild(out);
});
</script>
"""


def find_browser() -> str | None:
    explicit = os.environ.get("STOCHPEND_BROWSER")
    if explicit:
        return shutil.which(explicit) or (explicit if os.path.isfile(explicit) else None)
    for name in BROWSERS:
        found = shutil.which(name)
        if found:
            return found
    return None


@pytest.fixture(scope="module")
def report(tiny_reproduce):
    """The session's tiny ``reproduce all`` (tests/conftest.py, shared with
    tests/unit/test_reproduce.py) and its report.html as it was written."""
    result, _, text = tiny_reproduce
    return result, text


def test_report_renders_in_headless_chromium(report, tmp_path) -> None:
    browser = find_browser()
    if browser is None:
        pytest.skip(f"no headless Chromium found (looked for $STOCHPEND_BROWSER and {', '.join(BROWSERS)} "
                    "on PATH); install Debian's 'chromium' package to run this test")
    result, text = report
    assert text.count("</body>") == 1
    page = tmp_path / "page.html"
    page.write_text(text.replace("</body>", CHECK_SCRIPT + "</body>"), encoding="utf-8")
    cmd = [
        browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}", "--dump-dom", page.as_uri(),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=180, check=False)
    match = re.search(r'<pre id="stochpend-checks">(.*?)</pre>', proc.stdout, re.S)
    assert match, f"no checks in the dumped DOM (exit {proc.returncode}): {proc.stderr[-2000:]}"
    checks = json.loads(html.unescape(match.group(1)))

    assert checks["images"] == 5 == text.count("data:image/png;base64,")  # 4 figures + exponents
    assert checks["bad_images"] == []
    assert all(w > 500 for w in checks["widths"]), checks["widths"]
    assert checks["tables"] == text.count("<table>")
    assert checks["cells"] == text.count("<td") + text.count("<th>") > 0
    assert checks["empty_cells"] == []
    # Every row of every figure table made it into the page.
    rows = sum(len(f.rows) for f in result.figures.values())
    assert text.count("<tr>") >= rows
