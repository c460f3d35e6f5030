"""Small helpers for self-contained HTML reports: one file, figures embedded as base64 PNG.

Generic on purpose (the campaign and diagnosis reports both use it): escaping,
tables, figures, sections and the page frame.  Nothing here knows about
calibration.

>>> from graph_calib.reports import html
>>> html.table(["a", "b"], [[1, "<x>"]])
'<table><thead><tr><th class="l">a</th><th>b</th></tr></thead><tbody><tr><td class="l">1</td><td>&lt;x&gt;</td></tr></tbody></table>'
"""

from __future__ import annotations

import base64
import html as _html
import io

#: Style of every report: readable on screen and on paper, no external resources.
CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 2em auto; max-width: 1150px;
       padding: 0 1em; color: #222; line-height: 1.45; }
h1 { font-size: 1.6em; border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { font-size: 1.3em; margin-top: 2em; border-bottom: 1px solid #bbb; }
h3 { font-size: 1.1em; margin-top: 1.5em; }
table { border-collapse: collapse; margin: .6em 0 1.2em 0; font-size: .88em; }
th, td { border: 1px solid #ccc; padding: .25em .55em; text-align: right; vertical-align: top; }
th { background: #f0f0f0; }
td.l, th.l { text-align: left; }
tr.bad td { background: #fde2e2; }
tr.warn td { background: #fff4d6; }
.ok { color: #176e2a; font-weight: bold; }
.fail { color: #b00020; font-weight: bold; }
.note { color: #555; font-size: .92em; }
figure { margin: 1em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: .9em; color: #444; margin-top: .3em; }
code { background: #f4f4f4; padding: 0 .2em; }
nav ul { columns: 2; font-size: .92em; }
"""


class Raw(str):
    """Text that is already HTML and must not be escaped again."""


def esc(value):
    """``value`` as HTML text (a :class:`Raw` passes through unchanged)."""
    if isinstance(value, Raw):
        return str(value)
    return _html.escape(str(value), quote=True)


def figure_png(fig, *, dpi=96):
    """PNG bytes of a matplotlib figure; the figure is closed afterwards."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)
    return buf.getvalue()


def png_data_uri(png):
    """A ``data:`` URI of PNG bytes."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def figure(fig, *, caption="", alt="", dpi=96, save_to=None):
    """A ``<figure>`` with ``fig`` embedded as PNG (and optionally also written to ``save_to``).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        Closed after rendering.
    caption : str
        Plain text (escaped) or :class:`Raw` HTML.
    alt : str
        Alternative text; the caption's text when empty.
    dpi : int
    save_to : str or Path, optional
        Also write the PNG there (atomically), e.g. to look at it outside the report.
    """
    png = figure_png(fig, dpi=dpi)
    if save_to is not None:
        from graph_calib.io import atomic_path

        with atomic_path(save_to) as tmp:
            tmp.write_bytes(png)
    alt_text = alt or (caption if not isinstance(caption, Raw) else "figure")
    cap = f"<figcaption>{esc(caption)}</figcaption>" if caption else ""
    return Raw(f'<figure><img alt="{esc(alt_text)}" src="{png_data_uri(png)}">{cap}</figure>')


def table(headers, rows, *, row_classes=None, left=(0,)):
    """An HTML table.

    Parameters
    ----------
    headers : sequence
        Column titles (escaped unless :class:`Raw`).
    rows : sequence of sequence
        Cells; numbers and text are escaped, :class:`Raw` passes through.
    row_classes : sequence of str, optional
        A CSS class per row (``"bad"``, ``"warn"`` or ``""``).
    left : tuple of int
        Columns aligned left (text columns).
    """
    def cell(tag, i, v):
        cls = ' class="l"' if i in left else ""
        return f"<{tag}{cls}>{esc(v)}</{tag}>"

    head = "".join(cell("th", i, h) for i, h in enumerate(headers))
    body = []
    for r, row in enumerate(rows):
        cls = row_classes[r] if row_classes is not None and row_classes[r] else ""
        attr = f' class="{cls}"' if cls else ""
        body.append(f"<tr{attr}>" + "".join(cell("td", i, v) for i, v in enumerate(row)) + "</tr>")
    return Raw(f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>")


def section(title, *parts, anchor=None, level=2):
    """A heading followed by ``parts`` (HTML or plain text paragraphs)."""
    a = f' id="{esc(anchor)}"' if anchor else ""
    inner = "\n".join(p if isinstance(p, Raw) else f"<p>{esc(p)}</p>" for p in parts)
    return Raw(f"<h{level}{a}>{esc(title)}</h{level}>\n{inner}")


def paragraph(text, *, cls=None):
    """A ``<p>``; ``text`` escaped unless :class:`Raw`."""
    c = f' class="{cls}"' if cls else ""
    return Raw(f"<p{c}>{esc(text)}</p>")


def verdict(ok, text_ok="pass", text_fail="FAIL"):
    """A green or red word."""
    return Raw(f'<span class="ok">{esc(text_ok)}</span>' if ok else f'<span class="fail">{esc(text_fail)}</span>')


def page(title, *parts):
    """A complete HTML document (UTF-8, the report style inlined)."""
    body = "\n".join(p if isinstance(p, Raw) else f"<p>{esc(p)}</p>" for p in parts)
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{esc(title)}</title><style>{CSS}</style></head>\n<body>\n<h1>{esc(title)}</h1>\n{body}\n"
            f"</body></html>\n")


__all__ = ["CSS", "Raw", "esc", "figure_png", "png_data_uri", "figure", "table", "section", "paragraph",
           "verdict", "page"]
