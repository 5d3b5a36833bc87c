"""One self-contained HTML page: inline CSS, plotly.js inlined once, images as data URIs, a small lightbox script.

Nothing on the page refers to another host: it opens offline and makes no network request. plotly.js (4.8 MB)
is inlined gzip-compressed and base64-encoded (about 1.9 MB) and inflated by the browser's DecompressionStream
when the page loads; figures are drawn once it has run (`onPlotly`).
"""
from __future__ import annotations

import base64
import gzip
import html
import json
import os
from functools import lru_cache
from pathlib import Path
from typing import Iterable

import plotly.graph_objects as go
from plotly.offline import get_plotlyjs

from reports.figures import PLOT_CONFIG
from utils.errors import UserError
from utils.io import atomic_write

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:0 auto;max-width:1280px;padding:12px 20px;
color:#222}
h1{font-size:1.5em;margin:.4em 0}h2{font-size:1.2em;margin:1.4em 0 .4em;border-bottom:1px solid #ddd}
table{border-collapse:collapse;font-size:.9em;margin:.4em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}
.note{background:#eef5ff;border-left:4px solid #4a90d9;padding:6px 10px;margin:6px 0}
.warn{background:#fff4e0;border-left:4px solid #e69500;padding:6px 10px;margin:6px 0}
.gallery{display:grid;grid-template-columns:repeat(4,minmax(0,1fr));gap:4px;align-items:start}
.gallery figure{margin:0}.gallery img{width:100%;cursor:zoom-in;display:block}
.gallery figcaption{font-size:.75em;color:#555}.gallery .head{font-weight:bold;font-size:.85em}
#lightbox{display:none;position:fixed;inset:0;background:rgba(0,0,0,.85);z-index:10;cursor:zoom-out;
align-items:center;justify-content:center;flex-direction:column}
#lightbox img{max-width:92vw;max-height:86vh;image-rendering:pixelated;min-width:50vmin}
#lightbox div{color:#eee;margin-top:8px}
details{margin:.5em 0}pre{font-size:.8em;background:#f7f7f7;padding:8px;overflow:auto}
.small{font-size:.85em;color:#555}
"""

PLOTLY_LOADER_JS = """
var plotlyQueue = [];
function onPlotly(draw) { if (window.Plotly) { draw(); } else { plotlyQueue.push(draw); } }
(async function () {
  var packed = document.getElementById('plotly-gz').textContent;
  var bytes = Uint8Array.from(atob(packed), function (c) { return c.charCodeAt(0); });
  var stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('gzip'));
  var code = await new Response(stream).text();
  var script = document.createElement('script');
  script.textContent = code;
  document.head.appendChild(script);
  plotlyQueue.forEach(function (draw) { draw(); });
  plotlyQueue = [];
})();
"""

LIGHTBOX_JS = """
document.addEventListener('click', function (ev) {
  var box = document.getElementById('lightbox');
  if (ev.target.classList && ev.target.classList.contains('zoom')) {
    box.querySelector('img').src = ev.target.src;
    box.querySelector('div').textContent = ev.target.alt;
    box.style.display = 'flex';
  } else if (box.contains(ev.target)) { box.style.display = 'none'; }
});
document.addEventListener('keydown', function (ev) {
  if (ev.key === 'Escape') document.getElementById('lightbox').style.display = 'none';
});
"""


@lru_cache(maxsize=1)
def packed_plotlyjs() -> str:
    """plotly.js (the version the plotly package ships), gzip-compressed and base64-encoded."""
    return base64.b64encode(gzip.compress(get_plotlyjs().encode("utf-8"), compresslevel=9, mtime=0)).decode("ascii")


def script_json(value: str) -> str:
    """JSON text made safe inside a <script> element."""
    return value.replace("</", "<\\/")


def esc(value: object) -> str:
    """HTML-escaped text of `value`."""
    return html.escape(str(value))


class Page:
    """Sections appended in order, rendered into one HTML document."""

    def __init__(self, title: str):
        self.title = title
        self.parts: list[str] = []

    def add(self, raw_html: str) -> None:
        """Append raw HTML (the caller escapes)."""
        self.parts.append(raw_html)

    def heading(self, text: str, level: int = 2) -> None:
        self.add(f"<h{level}>{esc(text)}</h{level}>")

    def paragraph(self, text: str, cls: str = "") -> None:
        self.add(f"<p class='{cls}'>{esc(text)}</p>" if cls else f"<p>{esc(text)}</p>")

    def box(self, text: str, kind: str = "note") -> None:
        """A highlighted line; kind 'note' (blue) or 'warn' (orange)."""
        self.add(f"<div class='{kind}'>{esc(text)}</div>")

    def absent(self, items: Iterable[str]) -> None:
        """One warning box per piece of the report's data that is missing ("absent: ...")."""
        for item in items:
            self.box(f"absent: {item}", "warn")

    def scene(self, note: str, fig: go.Figure) -> None:
        """The "Scene and cameras" section: its note and the 3D figure (`reports.figures.scene_figure`)."""
        self.heading("Scene and cameras")
        self.paragraph(note, "small")
        self.figure(fig, "scene3d")

    def table(self, headers: Iterable[str], rows: Iterable[Iterable[object]], raw: bool = False) -> None:
        """A table; cells are escaped unless `raw`."""
        cell = (lambda v: str(v)) if raw else esc
        head = "".join(f"<th>{esc(h)}</th>" for h in headers)
        body = "".join("<tr>" + "".join(f"<td>{cell(v)}</td>" for v in row) + "</tr>" for row in rows)
        self.add(f"<table><tr>{head}</tr>{body}</table>")

    def figure(self, fig: go.Figure, div_id: str) -> None:
        """A plotly figure, drawn once plotly.js is loaded (it is inlined once in the page head)."""
        self.add(f"<div id='{div_id}' class='plot'></div><script>onPlotly(function () {{"
                 f"var fig = {script_json(fig.to_json())};"
                 f"Plotly.newPlot('{div_id}', fig.data, fig.layout, {json.dumps(PLOT_CONFIG)});}});</script>")

    def render(self) -> str:
        """The whole document."""
        return ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
                f"<meta name='viewport' content='width=device-width,initial-scale=1'><title>{esc(self.title)}</title>"
                f"<style>{CSS}</style><script id='plotly-gz' type='application/octet-stream'>{packed_plotlyjs()}</script>"
                f"<script>{PLOTLY_LOADER_JS}</script></head><body>"
                f"<h1>{esc(self.title)}</h1>{''.join(self.parts)}"
                "<div id='lightbox'><img alt=''><div></div></div>"
                f"<script>{LIGHTBOX_JS}</script></body></html>")

    def write(self, path: str | os.PathLike) -> Path:
        """Write the page atomically (a reader never sees half a report).

        Raises:
            UserError: the path cannot be written.
        """
        path = Path(path)
        text = self.render()

        def _write(tmp: str) -> None:
            with open(tmp, "w", encoding="utf-8") as fh:
                fh.write(text)
        try:
            atomic_write(path, _write)
        except OSError as exc:
            raise UserError(f"cannot write the report to {path} ({exc.strerror or exc}); pass -o with a writable "
                            "path") from None
        return path


def image_cell(uri: str, caption: str) -> str:
    """A gallery cell: a clickable (enlarging) image with a caption."""
    return (f"<figure><img class='zoom' src='{uri}' alt='{esc(caption)}' loading='lazy'>"
            f"<figcaption>{esc(caption)}</figcaption></figure>")
