"""A self-contained HTML page (figures referenced by relative paths) with an image-load self-check.

On load, a small script counts the ``<img>`` elements that are complete with a natural width > 0 and
writes the counts into ``<body data-images-total=.. data-images-loaded=..>`` and a visible line, so a
headless browser (``chromium --headless --dump-dom``) can verify that every figure loads.
"""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path

from ..io.atomic import write_text

__all__ = ["Section", "render_page", "write_page", "table_html"]

_CHECK_SCRIPT = """
<script>
function sotAppsImageCheck() {
  var imgs = Array.prototype.slice.call(document.images);
  var loaded = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length;
  document.body.setAttribute('data-images-total', String(imgs.length));
  document.body.setAttribute('data-images-loaded', String(loaded));
  var line = document.getElementById('image-check');
  if (line) { line.textContent = loaded + ' of ' + imgs.length + ' figures loaded'; }
}
window.addEventListener('load', sotAppsImageCheck);
</script>
"""

_STYLE = """
body { font-family: sans-serif; margin: 24px auto; max-width: 1100px; color: #222; line-height: 1.4; }
h1 { font-size: 1.6em; } h2 { margin-top: 1.6em; border-bottom: 1px solid #ddd; }
img { max-width: 100%; border: 1px solid #eee; }
table { border-collapse: collapse; margin: 8px 0; font-size: 0.9em; }
td, th { border: 1px solid #ccc; padding: 3px 8px; text-align: right; } th { background: #f4f4f4; }
td:first-child, th:first-child { text-align: left; }
.note { color: #666; font-size: 0.9em; } code { background: #f4f4f4; padding: 1px 4px; }
"""


@dataclass
class Section:
    title: str
    paragraphs: list[str] = field(default_factory=list)      # raw HTML allowed (already escaped by the caller)
    images: list[tuple[str, str]] = field(default_factory=list)  # (relative path, caption)
    tables: list[str] = field(default_factory=list)          # HTML from table_html


def table_html(header: list[str], rows: list[list[object]]) -> str:
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def render_page(title: str, intro: list[str], sections: list[Section]) -> str:
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             f"<title>{html.escape(title)}</title><style>{_STYLE}</style>{_CHECK_SCRIPT}</head><body>",
             f"<h1>{html.escape(title)}</h1>"]
    parts += [f"<p>{p}</p>" for p in intro]
    parts.append('<p class="note" id="image-check">figures not checked yet</p>')
    for s in sections:
        parts.append(f"<h2>{html.escape(s.title)}</h2>")
        parts += [f"<p>{p}</p>" for p in s.paragraphs]
        parts += s.tables
        for src, caption in s.images:
            parts.append(f'<figure><img src="{html.escape(src)}" alt="{html.escape(caption)}">'
                         f"<figcaption class=\"note\">{html.escape(caption)}</figcaption></figure>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_page(path: str | Path, title: str, intro: list[str], sections: list[Section]) -> Path:
    path = Path(path)
    for s in sections:
        for src, _ in s.images:
            if Path(src).is_absolute() or not (path.parent / src).is_file():
                raise FileNotFoundError(f"report figure {src} is not a file next to {path}")
    write_text(path, render_page(title, intro, sections))
    return path
