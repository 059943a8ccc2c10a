"""The report's two renderings of the same content: ``report.md`` and the self-contained ``index.html``.

Contract
--------
:func:`markdown_page` and :func:`html_page` lay out the introduction, the claims table, the
stages' run times and every section (paragraphs, tables with cells by :func:`format_cell`,
figures) in the same order. The HTML page embeds the figures and the animation as data URIs,
so it opens from disk with no server and no network; Jinja2 escapes every value.
"""

from __future__ import annotations

import base64
import math
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__
from ..io import REFERENCES
from ..params import ChainParams
from .claims import CLAIMS_HEADER
from .stages import Section


def format_cell(value: Any) -> str:
    """How a table cell is printed in both renderings: numbers to 6 significant digits (every digit is in
    summary.json and data/), None as a dash."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    if isinstance(value, bool | np.bool_):
        return str(bool(value))
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        return f"{float(value):.6g}"
    return str(value)


def _intro(params: ChainParams) -> str:
    return (
        f'cosserat-chain {__version__} reproduces "Modeling of static deformations and dynamics of localized rotation '
        f'in a chain of finite size particles": {params.n_particles} particles (N = {params.N}), E1 = {params.E1:g}, E2 = {params.E2:g}, h = {params.h:g}, a = {params.a:g}, b = {params.b:g}, '
        f"m = {params.m:g}, j = {params.j:.6g}, damping gamma = ({params.gamma_u:g}, {params.gamma_v:g}, {params.gamma_phi:g}). "
        "All numbers are in summary.json and data/; the resolved parameters in params.json. "
        f"Please cite: {REFERENCES}; and the package (CITATION.cff)."
    )


def _anchor(index: int) -> str:
    return f"section-{index + 1}"


def markdown_page(sections: list[Section], params: ChainParams, table: list[list[str]]) -> str:
    lines = ["# Reproduction of the paper", "", _intro(params), "", "## Contents", ""]
    lines += [f"{i + 1}. [{s.title}](#{_anchor(i)})" for i, s in enumerate(sections)]
    lines += ["", "## The paper's claims", "", "| " + " | ".join(CLAIMS_HEADER) + " |", "|---|---|---|"]
    lines += ["| " + " | ".join(row) + " |" for row in table]
    lines += ["", "| stage | seconds | status |", "|---|---|---|"]
    lines += [f"| {s.title} | {s.seconds:.1f} | {'failed' if s.error else 'ok'} |" for s in sections]
    for i, s in enumerate(sections):
        lines += ["", f'<a id="{_anchor(i)}"></a>', "", f"## {s.title}", ""]
        if s.error:
            lines += ["**This stage failed:**", "", "```", s.error.strip(), "```"]
            continue
        for paragraph in s.paragraphs:
            lines += [paragraph, ""]
        for caption, header, rows in s.tables:
            lines += [f"*{caption}*", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
            lines += ["| " + " | ".join(format_cell(v) for v in row) + " |" for row in rows]
            lines.append("")
        for stem, caption in s.figures:
            lines += [f"![{caption}](figures/{stem}.png)", "", f"*{caption}* ([SVG](figures/{stem}.svg))", ""]
    return "\n".join(lines) + "\n"


#: The page: a viewport for phones, figures and the animation no wider than the window, wide tables
#: scrolling inside themselves. Jinja2 escapes every value (autoescape); ``embedded`` holds the
#: figures as data URIs, so the page opens from disk with no server.
PAGE = """<!DOCTYPE html>
<html lang='en'>
<head>
<meta charset='utf-8'>
<meta name='viewport' content='width=device-width, initial-scale=1'>
<title>cosserat-chain: reproduction of the paper</title>
<style>
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; line-height: 1.45; }
img { max-width: 100%; height: auto; }
figure { margin: 1em 0; }
table { border-collapse: collapse; margin: 1em 0; display: block; overflow-x: auto; max-width: 100%; }
td, th { border: 1px solid #bbb; padding: 3px 8px; text-align: left; }
th { background: #eee; }
.error { background: #fee; border: 1px solid #c00; padding: 1em; white-space: pre-wrap; overflow-x: auto; }
</style>
</head>
<body>
<h1>Reproduction of the paper</h1>
<p>{{ intro }}</p>
<h2>Contents</h2>
<ol>
{%- for s in sections %}
<li><a href='#{{ s.anchor }}'>{{ s.title }}</a></li>
{%- endfor %}
</ol>
<h2>The paper's claims</h2>
<table>
<tr>{% for h in claims_header %}<th>{{ h }}</th>{% endfor %}</tr>
{%- for row in claims %}
<tr>{% for cell in row %}<td>{{ cell }}</td>{% endfor %}</tr>
{%- endfor %}
</table>
<table>
<tr><th>stage</th><th>seconds</th><th>status</th></tr>
{%- for s in sections %}
<tr><td>{{ s.title }}</td><td>{{ "%.1f" | format(s.seconds) }}</td><td>{{ "failed" if s.error else "ok" }}</td></tr>
{%- endfor %}
</table>
{%- for s in sections %}
<h2 id='{{ s.anchor }}'>{{ s.title }}</h2>
{%- if s.error %}
<p><b>This stage failed:</b></p>
<div class='error'>{{ s.error }}</div>
{%- else %}
{%- for paragraph in s.paragraphs %}
<p>{{ paragraph.text }}{% if paragraph.animation %}<br><img alt='animation of the rotating chain' src='data:image/gif;base64,{{ paragraph.animation }}'>{% endif %}</p>
{%- endfor %}
{%- for table in s.tables %}
<p><i>{{ table.caption }}</i></p>
<table>
<tr>{% for h in table.header %}<th>{{ h }}</th>{% endfor %}</tr>
{%- for row in table.rows %}
<tr>{% for cell in row %}<td>{{ cell }}</td>{% endfor %}</tr>
{%- endfor %}
</table>
{%- endfor %}
{%- for figure in s.figures %}
<figure><img alt='{{ figure.caption }}' src='data:image/png;base64,{{ figure.png }}'><figcaption>{{ figure.caption }} (<a href='figures/{{ figure.stem }}.svg'>SVG</a>)</figcaption></figure>
{%- endfor %}
{%- endif %}
{%- endfor %}
</body>
</html>
"""

#: Where a paragraph names the animation, the page shows it.
ANIMATION_LINK = "[figures/rotation.gif](figures/rotation.gif)"


def html_page(sections: list[Section], params: ChainParams, out: Path, table: list[list[str]]) -> str:
    import jinja2

    def embedded(path: Path) -> str | None:
        return base64.b64encode(path.read_bytes()).decode() if path.exists() else None

    def paragraph(text: str) -> dict[str, Any]:
        if ANIMATION_LINK not in text:
            return {"text": text, "animation": None}
        animation = embedded(out / "figures" / "rotation.gif")
        shown = "figures/rotation.gif" if animation else "(animation missing)"
        return {"text": text.replace(ANIMATION_LINK, shown), "animation": animation}

    pages = [
        {
            "anchor": _anchor(i),
            "title": s.title,
            "seconds": s.seconds,
            "error": s.error.strip() if s.error else None,
            "paragraphs": [paragraph(text) for text in s.paragraphs],
            "tables": [{"caption": c, "header": h, "rows": [[format_cell(v) for v in row] for row in rows]} for c, h, rows in s.tables],
            "figures": [{"stem": stem, "caption": c, "png": embedded(out / "figures" / f"{stem}.png")} for stem, c in s.figures],
        }
        for i, s in enumerate(sections)
    ]
    template = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined).from_string(PAGE)
    return template.render(intro=_intro(params), sections=pages, claims_header=CLAIMS_HEADER, claims=table)
