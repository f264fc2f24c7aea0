"""The HTML summary page of `progmo bench` (one self-contained file next to the CSVs and PNGs)."""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from .common import Provenance


def _num(x, fmt="{:.2e}"):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "n/a"
    return fmt.format(x)


def _table(header, rows) -> str:
    h = "".join(f"<th>{html.escape(str(c))}</th>" for c in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{h}</tr>{body}</table>"


def write(out: Path, prov: Provenance, sections: list[tuple[str, str]], omissions: list[str],
          elapsed_s: float) -> Path:
    """sections: (title, inner html). Ends with the rerun command, versions and omissions."""
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>progmo bench</title>",
        "<style>body{font-family:sans-serif;max-width:1200px;margin:1em auto}"
        "table{border-collapse:collapse;font-size:12px;margin:.5em 0}td,th{border:1px solid #ccc;padding:2px 6px}"
        "img{max-width:100%}code,pre{background:#f4f4f4}</style></head><body>",
        "<h1>progmo bench: speed against error</h1>",
        f"<p>Rerun: <code>{html.escape(prov.command)}</code> "
        f"(equivalently <code>{html.escape(prov.python_command)}</code>). Run time {elapsed_s:.0f} s.</p>",
    ]
    for title, inner in sections:
        parts.append(f"<h2>{html.escape(title)}</h2>{inner}")
    parts.append("<h2>Omissions</h2><ul>" + "".join(f"<li>{html.escape(o)}</li>" for o in omissions) + "</ul>")
    parts.append("<h2>Provenance</h2><pre>" + html.escape("\n".join(prov.lines())) + "</pre>")
    parts.append("</body></html>")
    p = out / "index.html"
    p.write_text("\n".join(parts))
    return p


def doc(text: str) -> str:
    """A module docstring as preformatted prose."""
    return f"<pre style='white-space:pre-wrap;background:none'>{html.escape(text.strip())}</pre>"


def img(name: str) -> str:
    return f"<p><img src='{html.escape(name)}' alt='{html.escape(name)}'></p>"


table = _table
num = _num
