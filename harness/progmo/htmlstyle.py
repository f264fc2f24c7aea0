"""The one look of progmo's HTML pages (the check report and the bench page): the style sheet and
the escaping helper both import, so the pages read alike."""

from __future__ import annotations

import html
from typing import Any

CSS = """
:root{--pass:#1e8449;--fail:#c0392b;--error:#8e1b5c;--skip:#7f8c8d;--reg:#d35400;--bg:#fafafa}
*{box-sizing:border-box}
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;margin:0;background:var(--bg);color:#222}
main{max-width:1180px;margin:0 auto;padding:20px 28px 40px}
h1{font-size:22px;margin:0 0 4px} h2{font-size:18px;margin:28px 0 10px;border-bottom:1px solid #ddd;padding-bottom:4px}
h3{font-size:15px;margin:16px 0 6px}
.banner{padding:12px 16px;border-radius:6px;color:#fff;font-weight:600;margin:12px 0;font-size:16px}
.banner.b-ok{background:var(--pass)} .banner.b-bad{background:var(--fail)}
.sub{color:#555;margin:0}
table{border-collapse:collapse;background:#fff;margin:6px 0 12px;font-size:13px}
th,td{border:1px solid #ddd;padding:4px 8px;text-align:left;vertical-align:top}
th{background:#f0f0f0;font-weight:600}
td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
.v{display:inline-block;min-width:64px;text-align:center;border-radius:4px;padding:1px 8px;color:#fff;font-weight:600;font-size:12px}
.v-pass{background:var(--pass)} .v-fail{background:var(--fail)} .v-error{background:var(--error)}
.v-declared{background:var(--skip)} .v-regression{background:var(--reg)} .v-not-run{background:#bbb}
.v-not_checked{background:var(--error)}
td.c-pass{background:#eaf6ee} td.c-warn{background:#fff4d6}
td.c-fail,td.c-error,td.c-not_checked{background:#fdecea} td.c-regression{background:#fdf0e6} td.c-declared{background:#f4f4f4} td.c-na{color:#999;text-align:center}
.reason.warnbox{background:#fff8e6;border-color:#e6a100}
.small{font-size:12px;color:#555}
.reason{font-family:ui-monospace,SFMono-Regular,Menlo,Consolas,monospace;font-size:12px;background:#fff6f5;border-left:3px solid var(--fail);padding:4px 8px;white-space:pre-wrap;word-break:break-word}
.reason.skip{background:#f5f5f5;border-color:var(--skip)}
.bad{color:var(--fail);font-weight:600} .warn{color:var(--reg);font-weight:600} .good{color:var(--pass)}
.bar{display:inline-block;height:8px;background:#e5e5e5;width:60px;border-radius:4px;vertical-align:middle;margin-right:6px;overflow:hidden}
.bar>i{display:block;height:100%;background:var(--pass)} .bar>i.warm{background:#e6a100} .bar>i.hot{background:var(--fail)}
details.scene{background:#fff;border:1px solid #e2e2e2;border-radius:6px;padding:6px 16px 12px;margin:14px 0}
details.scene.attn{border-left:5px solid var(--fail)}
details.scene>summary{cursor:pointer} details.scene>summary>h3{display:inline}
.sim{border-top:1px dashed #e2e2e2;padding-top:6px;margin-top:8px}
img.plot{max-width:100%;display:block;margin:4px 0}
ul.notes{margin:4px 0 8px 18px;padding:0;font-size:12px;color:#444}
pre{background:#272822;color:#f8f8f2;padding:10px 12px;border-radius:5px;overflow-x:auto;font-size:12.5px}
footer{margin-top:30px;border-top:2px solid #ccc;padding-top:8px}
a{color:#1a5fa8;text-decoration:none} a:hover{text-decoration:underline}
tr.t-met td{background:#eaf6ee} tr.t-missed td{background:#fdecea} tr.t-not-measured td{background:#f4f4f4}
table.keys{table-layout:fixed;width:100%} table.keys td{word-break:break-word;overflow-wrap:anywhere}
table.keys td.k{width:22%;font-weight:600}
p.zero-note{font-size:12px;color:#444;margin:0 0 10px}
pre.doc{background:none;color:#222;white-space:pre-wrap;padding:0;font-size:13px}
"""


def esc(s: Any) -> str:
    """HTML-escaped text (quotes too: safe in attributes)."""
    return html.escape(str(s), quote=True)
