"""A study report as one self-contained HTML page: the same parts as report.md (report's
Doc), tables as HTML tables, plots inline as base64 PNG data URIs (no file beside it needed; a
browser opens it offline), a little CSS for legible tables, and one inline line of script that reports on the console any
plot the browser could not decode (what a headless check of the page looks for)."""
from __future__ import annotations

import base64
import html
from typing import Any

STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1200px; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f0f0f0; }
td:first-child, th:first-child { text-align: left; }
figure { display: inline-block; margin: 0.5em 1em 1em 0; }
figcaption { font-size: 0.85em; color: #555; }
img { max-width: 100%; }
"""
# console.error for an image that did not decode: a headless browser check greps for it
CHECK = ("window.addEventListener('load', () => { for (const i of document.images) "
         "{ if (!i.complete || i.naturalWidth === 0) console.error('REPORT ERROR: plot not decoded: ' + i.alt); } "
         "console.log('report loaded: ' + document.images.length + ' plots, ' + "
         "document.querySelectorAll('table').length + ' tables'); });")


def _image(path: Any) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f"data:image/png;base64,{data}"


def to_html(doc: Any, title: str) -> str:
    """The page of a report.Doc."""
    e = html.escape
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           f"<title>{e(title)}</title>", f"<style>{STYLE}</style>", "</head>", "<body>"]
    for kind, x in doc.parts:
        if kind in ("h1", "h2", "h3"):
            out.append(f"<{kind}>{e(x)}</{kind}>")
        elif kind == "p":
            out.append(f"<p>{e(x)}</p>")
        elif kind == "table":
            heads, rows = x
            out.append("<table>")
            out.append("<thead><tr>" + "".join(f"<th>{e(h)}</th>" for h in heads) + "</tr></thead>")
            out.append("<tbody>")
            out += ["<tr>" + "".join(f"<td>{e(c)}</td>" for c in r) + "</tr>" for r in rows]
            out.append("</tbody></table>")
        elif kind == "img":
            caption, path, _ = x
            out.append(f'<figure><img src="{_image(path)}" alt="{e(caption)}">'
                       f"<figcaption>{e(caption)}</figcaption></figure>")
        elif kind == "ul":
            out.append("<ul>" + "".join(f"<li>{e(i)}</li>" for i in x) + "</ul>")
    out += [f"<script>{CHECK}</script>", "</body>", "</html>", ""]
    return "\n".join(out)
