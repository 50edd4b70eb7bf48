"""The report page's HTML primitives: its style sheet, a table, an embedded PNG and a number
as the page shows it ("-" when it is not known)."""

from __future__ import annotations

import base64
import html
import math
import os

#: The page's style sheet (the flags, notes and verdicts take their colours from it).
STYLE = """body{font-family:sans-serif;margin:2em;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em;font-size:0.9em}
td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}th{background:#eee}
td.l,th.l{text-align:left}.flag{color:#a00;font-weight:bold}.ok{color:#070}
.note{color:#735200}.bad{color:#a00;font-weight:bold}.good{color:#070;font-weight:bold}
.caution{color:#735200;font-weight:bold}table.summary{font-size:1em;width:100%}
table.summary td,table.summary th{vertical-align:top;text-align:left;padding:6px 8px}
table.summary td:nth-child(2){white-space:nowrap}
table.source td{text-align:left}table.source th{text-align:left;font-weight:normal}
.small{font-size:0.85em;color:#555}
img{max-width:100%;border:1px solid #ddd;margin:0.5em 0}h2{border-bottom:2px solid #ccc}"""


def image_html(path, alt):
    """A PNG file embedded as data (the page stands alone); nothing when there is no file."""
    if not os.path.exists(path):
        return ""
    with open(path, "rb") as fh:
        data = base64.b64encode(fh.read()).decode()
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


def table_html(header, rows, left=(), cls=None, raw=()):
    """An HTML table: ``header`` then ``rows``; columns in ``left`` aligned left; cells of
    columns in ``raw`` are HTML already (everything else is escaped)."""
    out = [f'<table{f" class={chr(34)}{cls}{chr(34)}" if cls else ""}>'
           + ("<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>"
              if header else "")]
    for row in rows:
        cells = [(c if i in raw else html.escape(str(c)), ' class="l"' if i in left else "")
                 for i, c in enumerate(row)]
        out.append("<tr>" + "".join(f"<td{a}>{c}</td>" for c, a in cells) + "</tr>")
    return "".join(out) + "</table>"


def number_text(x, spec=".4g"):
    """A number as the page shows it, by ``spec``; "-" when it is None or not finite."""
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)
