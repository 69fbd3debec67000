"""The self-contained HTML report of :func:`stochpend.paper.reproduce.reproduce`.

One file, ``OUT/report.html``: every figure embedded as a base64 PNG, every table, the
parameters, seeds, run times and versions. No scripts, no external resources, no server: it
opens from disk in any browser.
"""

from __future__ import annotations

import base64
import html
import math
import re
import time
from pathlib import Path
from typing import Any

from stochpend.files._files import write_atomic
from stochpend.paper.figures._common import COLUMNS, DASH, fmt_num, fmt_se
from stochpend.text.equations import with_numbers

__all__ = ["build_report", "write_report"]

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 2em auto;
       max-width: 1200px; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { font-size: 1.6em; } h2 { margin-top: 2em; border-bottom: 1px solid #ccc; }
figure { margin: 1em 0; } figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: 0.92em; color: #333; margin-top: 0.4em; }
table { border-collapse: collapse; font-size: 0.84em; margin: 0.8em 0; }
th, td { border: 1px solid #ccc; padding: 3px 6px; text-align: left; vertical-align: top; }
th { background: #f1f1f1; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.ok { background: #e3f4e3; } td.warn { background: #fff3cd; } td.bad { background: #f8d7da; }
.banner { background: #fff3cd; border: 1px solid #e0c068; padding: 0.6em 1em; }
.small { font-size: 0.85em; color: #555; }
"""


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


_SUP = re.compile(r"\^\{([^{}]*)\}|\^\(([^()]*)\)|\^(-?[0-9]+(?:\.[0-9]+)?)")
_SUB = re.compile(r"_\{([^{}]*)\}")


def _text(x: Any) -> str:
    """Prose for the page: escaped, the paper's labels as its printed equation numbers
    (:func:`stochpend.paper.with_numbers`), and the plain-text mathematics of the captions
    rendered: ``(Dt/τ²)^{1/2}`` as a superscript, ``t_{c}`` as a subscript; no script, no
    network at view time."""
    out = _e(with_numbers(str(x)))
    out = _SUP.sub(lambda m: f"<sup>{next(g for g in m.groups() if g is not None)}</sup>", out)
    return _SUB.sub(r"<sub>\1</sub>", out)


def _dev_class(text: str) -> str:
    try:
        d = abs(float(text))
    except ValueError:
        return "num"
    if not math.isfinite(d):
        return "num"
    return "num ok" if d <= 2 else ("num warn" if d <= 3 else "num bad")


def _table(header: list[str], rows: list[list[str]], classes: list[list[str]] | None = None) -> str:
    out = ["<table>", "<thead><tr>" + "".join(f"<th>{_text(h)}</th>" for h in header) + "</tr></thead>", "<tbody>"]
    for i, row in enumerate(rows):
        cells = []
        for j, c in enumerate(row):
            text = c if str(c).strip() else DASH
            cls = classes[i][j] if classes else ""
            cells.append(f'<td class="{cls}">{_text(text)}</td>' if cls else f"<td>{_text(text)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def _figure_table(rows: list[Any]) -> str:
    body, classes = [], []
    for r in rows:
        cells = r.cells()
        body.append(cells)
        cls = ["", "", "num", "num", "", "", "", "num", _dev_class(cells[8]), _dev_class(cells[9])]
        classes.append(cls)
    return _table(list(COLUMNS), body, classes)


def _fmt_float(x: Any, figure_run: str = ".3g") -> str:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return DASH
    return format(v, figure_run) if math.isfinite(v) else DASH


def _runs_table(records: list[Any]) -> str:
    header = ["File", "Physics", "Paths", "Times", "Seed", "Batches", "Status", "Wall time (s)",
              "Path-steps", "Non-finite paths", "Bias of ⟨E⟩ at the last t", "Created"]
    rows = []
    for r in records:
        a = r.attrs
        s = r.figure_run
        rows.append([
            r.path.name,
            s.describe(),
            str(s.paths),
            f"{len(s.times())} log-spaced in [{s.t_min:g}, {fmt_num(s.t_max)}]",
            str(s.seed),
            str(a.get("n_batches", DASH)),
            r.status,
            _fmt_float(a.get("wall_time_s"), ".1f"),
            _fmt_float(a.get("path_steps"), ".3g"),
            str(r.nonfinite_paths),
            _bias_text(getattr(r, "late_bias", None)),
            str(a.get("created", DASH)),
        ])
    return _table(header, rows)


def _bias_text(late: tuple[float, float, int] | None) -> str:
    """The discretisation bias of <E> at a run's last output time, with what the estimate
    says (stochpend.bias.assess): 'certified small', 'significant' or 'unresolved'."""
    from stochpend.runs import bias

    if late is None:
        return DASH
    value, error, verdict = late
    word = {bias.CERTIFIED_SMALL: "certified small", bias.SIGNIFICANT: "significant"}.get(verdict, "unresolved")
    return f"{fmt_se(value, error)} ({word})"


def _image(path: Path, alt: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img alt="{_e(alt)}" src="data:image/png;base64,{data}">'


def _sim_total(result: Any) -> float:
    return float(sum(r.wall_time_s for r in result.runs.values() if math.isfinite(r.wall_time_s)))


def _steps_total(result: Any) -> float:
    return float(sum(r.path_steps for r in result.runs.values() if math.isfinite(r.path_steps)))


#: The report's closing notes (prose: labels become equation numbers, ^{...} superscripts).
_NOTES = (
    "Initial conditions (the paper states none): θ(0) uniform on [−π, π), Ω(0) = 0, and for OU "
    "noise ξ(0) drawn from its stationary law N(0, D/(2τ)). (θ, Ω) = (0, 0) is a fixed point "
    "that the multiplicative noise cannot leave.",
    "The printed closed form of the OU skewness (eq:skewEcolor) has a typo; the value used "
    "here, 2.028 = Γ(7/4) Γ(1/4)^{1/2}/Γ(5/4)^{3/2} = 6√2π/Γ(1/4)², is the paper's quoted one.",
    "First-order averaging (diff1, quad1, PDFav1) is shown for contrast: the paper explains "
    "why its prefactors are wrong; the tables show which set the data select.",
    "Standard errors: delete-one-batch jackknife over the run's batches. Equation numbers are "
    "those of the printed paper (the code and the docs cite the LaTeX source's labels: "
    "stochpend.paper.EQUATIONS maps one to the other).",
)


def build_report(result: Any) -> str:
    """The report as one HTML string (see :func:`write_report`)."""
    settings = result.settings
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>stochpend — reproduction of Mallick &amp; Marcq (2004)</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>Stochastic pendulum with Ornstein–Uhlenbeck noise — reproduction of the figures</h1>",
        "<p>K. Mallick and P. Marcq, <i>On the stochastic pendulum with Ornstein–Uhlenbeck noise</i> "
        "(2004). Model: dΩ/dt = −(ω² + ξ) sin θ, dθ/dt = Ω; E = Ω²/2 − ω² cos θ. "
        "S = ⟨E³⟩/⟨E²⟩<sup>3/2</sup> and F = ⟨E⁴⟩/⟨E²⟩² are raw-moment ratios, as in the paper "
        f"({with_numbers('Eqs. eq:skewEblanc, eq:flatEblanc')}).</p>",
        f'<p class="small">Generated {_e(time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()))} by '
        f"stochpend {_e(result.versions.get('stochpend', '?'))}; wall time of this call "
        f"{result.wall_time_s:.1f} s; the runs' own simulation times add up to {_sim_total(result):.0f} s "
        f"({_steps_total(result):.3g} path-steps), whether simulated now or read from the cache.</p>",
    ]
    if "exponents" in result.figures:
        parts.append("<p>Beyond the paper, the last section compares the measured long-time growth of ⟨E⟩ "
                     "with the predicted law for the pendulum with four noises and for the harmonic and "
                     "quartic oscillators (derivations: docs/scaling.md; models: docs/models.md). Its runs "
                     "have their own sizes, given in its caption.</p>")
    if settings.get("quick"):
        parts.append('<p class="banner"><b>Quick mode</b>: small ensembles and short times — a smoke '
                     "test of the pipeline, not a reproduction. The tables are filled but the late-time "
                     "values are far from converged.</p>")
    parts.append("<h2>Settings</h2>")
    parts.append(_table(["Setting", "Value"], [
        ["figures", ", ".join(settings["figures"])],
        ["paths per run", str(settings["paths"])],
        ["t_max override", DASH if settings["t_max"] is None else f"{settings['t_max']:g}"],
        ["quick", str(settings["quick"])],
        ["force", str(settings["force"])],
        ["output directory", settings["out"]],
    ]))
    parts.append("<ul>" + "".join(
        f'<li><a href="#{_e(f.name)}">{_e(f.title)}</a></li>' for f in result.figures.values()) + "</ul>")
    for f in result.figures.values():
        parts += [
            f'<h2 id="{_e(f.name)}">{_e(f.title)}</h2>',
            "<figure>",
            _image(f.png, f.title),
            f"<figcaption>{_text(f.caption)}</figcaption>",
            "</figure>",
            f'<p class="small">Files: <a href="{_e(f.pdf.name)}">{_e(f.pdf.name)}</a>, '
            f'<a href="{_e(f.png.name)}">{_e(f.png.name)}</a>, '
            f'<a href="{_e(f.table_csv.name)}">{_e(f.table_csv.name)}</a>. '
            f"Figure wall time {f.wall_time_s:.1f} s (simulations of this call included).</p>",
            "<h3>Late-time values against the predictions</h3>",
            _figure_table(f.rows),
            f'<p class="small">{_text(f.fit_method)} Deviation cells: green |dev| ≤ 2, yellow ≤ 3, '
            f"red &gt; 3 standard errors.</p>",
            "<h3>Runs</h3>",
            _runs_table(f.runs),
        ]
    parts.append("<h2>Versions and machine</h2>")
    parts.append(_table(["Item", "Value"], [[k, v] for k, v in result.versions.items()]))
    parts.append(
        "<h2>Notes</h2><ul>" + "".join(f"<li>{_text(item)}</li>" for item in _NOTES) + "</ul>"
    )
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(result: Any, path: str | Path | None = None) -> Path:
    """Write the report (default ``result.report``) and return its path."""
    p = Path(path) if path is not None else Path(result.report)
    return write_atomic(p, build_report(result).encode("utf-8"), overwrite=True)
