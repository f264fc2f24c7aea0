"""The HTML summary page of `progmo bench` (one self-contained file next to the CSVs and PNGs), in
the check report's style (progmo.htmlstyle): targets as a coloured table (met / missed by how much /
not measured), key numbers as a wrapping table, values formatted for prose (never a Python repr),
and a note under each log-scale figure with exact zeros (drawn on the axis floor, bench.common.log_plot)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..htmlstyle import CSS, esc
from .common import ZERO_LABEL, Provenance


def _num(x, fmt="{:.2e}"):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "n/a"
    return fmt.format(x)


def prose(x: Any) -> str:
    """A value for a sentence, escaped: mappings as "key value, key value", sequences joined by
    commas, floats in 3 significant digits (never Python's dict/list repr)."""
    def one(v: Any) -> str:
        if isinstance(v, dict):
            return ", ".join(f"{k} {one(w)}" for k, w in v.items())
        if isinstance(v, (list, tuple)):
            return ", ".join(one(w) for w in v)
        if isinstance(v, (float, np.floating)):
            return _num(float(v), "{:.3g}")
        return str(v)
    return esc(one(x))


def _table(header, rows) -> str:
    h = "".join(f"<th>{esc(c)}</th>" for c in header)
    body = "".join("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>"


_BADGE = {"met": "v-pass", "missed": "v-fail", "not measured": "v-declared"}


def targets_table(targets: Sequence[Any]) -> str:
    """The targets, one row each, coloured by status (rows `t-met`, `t-missed`, `t-not-measured`):
    verdict badge, how far off, the target and the measured figure."""
    rows = []
    for t in targets:
        st = t.status
        rows.append(f"<tr class='t-{st.replace(' ', '-')}'><td><span class='v {_BADGE[st]}'>{esc(st)}</span></td>"
                    f"<td>{esc(t.how_far)}</td><td>{esc(t.target)}</td><td>{esc(t.measured)}</td></tr>")
    n = {s: sum(t.status == s for t in targets) for s in _BADGE}
    return (f"<p class='sub'>{n['met']} met, {n['missed']} missed, {n['not measured']} not measured.</p>"
            "<table id='targets'><thead><tr><th>verdict</th><th>how far</th><th>target</th>"
            "<th>measured (this run)</th></tr></thead><tbody>" + "".join(rows) + "</tbody></table>")


def key_numbers(lines: Sequence[str]) -> str:
    """The run's key numbers (the lines printed on stdout) as a fixed-width wrapping table: "part:
    text" lines as (part, text); indented "a | b | c" lines (a text table) as their own table."""
    out: list[str] = []
    rows: list[str] = []
    sub: list[list[str]] = []

    def flush_sub():
        if sub:
            rows.append("<tr><td class='k'></td><td>" + _table(sub[0], sub[1:]) + "</td></tr>")
            sub.clear()

    for line in lines:
        if line.startswith("  ") and " | " in line:
            sub.append([c.strip() for c in line.split(" | ")])
            continue
        flush_sub()
        k, _, v = line.partition(": ")
        rows.append(f"<tr><td class='k'>{esc(k)}</td><td>{esc(v)}</td></tr>")
    flush_sub()
    out.append("<table class='keys' id='key-numbers'><tbody>" + "".join(rows) + "</tbody></table>")
    return "".join(out)


def zero_note(n: int) -> str:
    """Under a log-scale figure: how many plotted values are exactly 0 and how they are drawn."""
    if n == 0:
        return ""
    return (f"<p class='zero-note' data-zeros='{n}'>{n} plotted value{'s' if n != 1 else ''} "
            f"{'are' if n != 1 else 'is'} {esc(ZERO_LABEL)} as &#9660;: a log axis has no place for 0.</p>")


def write(out: Path, prov: Provenance, sections: list[tuple[str, str]], omissions: list[str],
          elapsed_s: float) -> Path:
    """sections: (title, inner html). Ends with the rerun command, versions and omissions."""
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width,initial-scale=1'><title>progmo bench</title>",
        f"<style>{CSS}</style></head><body><main>",
        "<h1>progmo bench: speed against error</h1>",
        f"<p class='sub'>Rerun: <code>{esc(prov.command)}</code> "
        f"(equivalently <code>{esc(prov.python_command)}</code>). Run time {elapsed_s:.0f} s.</p>",
    ]
    for title, inner in sections:
        parts.append(f"<h2>{esc(title)}</h2>{inner}")
    parts.append("<h2>Omissions</h2><ul class='notes'>" + "".join(f"<li>{esc(o)}</li>" for o in omissions) + "</ul>")
    parts.append("<footer><h2>Provenance</h2><pre>" + esc("\n".join(prov.lines())) + "</pre></footer>")
    parts.append("</main></body></html>")
    p = out / "index.html"
    p.write_text("\n".join(parts))
    return p


def doc(text: str) -> str:
    """A module docstring as preformatted prose."""
    return f"<pre class='doc'>{esc(text.strip())}</pre>"


def img(name: str) -> str:
    return f"<p><img class='plot' src='{esc(name)}' alt='{esc(name)}'></p>"


table = _table
num = _num
