"""HTML pieces every result shares: escaping, tables, lines of words, the summary block.

The result types' ``_repr_html_`` (a notebook's view of an identification, a twin or a diagnosis) and
the report page of :mod:`momentid.report` are built from these, so a notebook and the page say the
same words.  Everything put into HTML goes through :func:`escape` unless it is :class:`Raw` (already
HTML made here): a trial called ``<b>x</b>`` shows as those characters, never as markup.
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

__all__ = ["Raw", "escape", "count", "channel_words", "table", "matrix_table", "word_lines", "warnings_list", "summary",
           "pm", "percent_pm", "SUMMARY_CSS", "REFUSED"]

#: How a damping ratio that is not an answer is marked (the words of the text table).
REFUSED = "NOT AN ANSWER"

#: The look of a summary block: in a notebook (scoped to the block) and on the report page.
SUMMARY_CSS = """
.momentid-summary { font-family: system-ui, sans-serif; line-height: 1.4; max-width: 60em; }
.momentid-summary .headline { font-size: 1.1em; font-weight: 600; margin: 0.3em 0; }
.momentid-summary table { border-collapse: collapse; margin: 0.4em 0; }
.momentid-summary th, .momentid-summary td { border-bottom: 1px solid #ccc; padding: 0.15em 0.6em;
  text-align: right; font-variant-numeric: tabular-nums; vertical-align: top; }
.momentid-summary td { white-space: nowrap; }
.momentid-summary td.name { white-space: normal; }
.momentid-summary th { background: #f2f2f2; }
.momentid-summary td.name, .momentid-summary th.name { text-align: left; }
.momentid-summary caption { text-align: left; font-weight: 600; padding: 0.2em 0; }
.momentid-summary .warning { color: #8a1c00; background: #fff1e6; border-left: 4px solid #c0392b;
  padding: 0.2em 0.5em; margin: 0.3em 0; list-style: none; }
.momentid-summary ul.warnings { padding-left: 0; }
.momentid-summary .refused { color: #a00; font-weight: 700; }
.momentid-summary .answer { color: #1e6b1e; }
.momentid-summary .note { color: #555; }
.momentid-summary .sub { margin-left: 1.5em; }
.momentid-summary p { margin: 0.25em 0; }
"""


class Raw(str):
    """A string that is already HTML (made by this module): :func:`escape` leaves it as it is."""


def escape(value: object) -> str:
    """``value`` as HTML text: ``<``, ``>``, ``&`` and quotes escaped; :class:`Raw` unchanged."""
    if isinstance(value, Raw):
        return str(value)
    return html.escape(str(value), quote=True)


def count(n: int, word: str) -> str:
    """``1 storey``, ``3 storeys``: ``n`` and ``word``, plural (with an ``s``) unless ``n`` is 1."""
    return f"{n} {word}{'' if n == 1 else 's'}"


def channel_words(channel: str) -> str:
    """A recorded channel in words: ``a2`` -> ``floor 2 sensor``, ``q2`` -> ``floor 2 displacement``,
    ``zdd`` -> ``table sensor``; any other name as it is."""
    if channel == "zdd":
        return "table sensor"
    kind = {"a": "sensor", "q": "displacement", "v": "velocity"}.get(channel[:1])
    return f"floor {channel[1:]} {kind}" if kind and channel[1:].isdigit() else channel


def pm(value: float, std: float | None, digits: int = 4) -> str:
    """``value ± std`` with ``digits`` decimals (``value`` alone when ``std`` is None or not finite)."""
    if std is None or not math.isfinite(float(std)):
        return f"{value:.{digits}f}"
    return f"{value:.{digits}f} ± {std:.{digits}f}"


def percent_pm(ratio: float, std: float | None, digits: int = 3) -> str:
    """A ratio (1) as ``percent ± percent`` (:func:`pm` of 100 x)."""
    return pm(100 * ratio, None if std is None else 100 * std, digits)


def table(columns: Sequence[str], rows: Iterable[Sequence], *, caption: str | None = None,
          names: int = 1, words: Sequence[int] = ()) -> str:
    """An HTML table: ``columns`` (headers, units in them), ``rows`` of cells (text, numbers as
    formatted text, or :class:`Raw`); the first ``names`` columns and those at ``words`` are words
    (left-aligned, wrapped), the others numbers (right-aligned, kept on one line)."""
    def cell(tag, i, value):
        cls = ' class="name"' if i < names or i in words else ""
        return f"<{tag}{cls}>{escape(value)}</{tag}>"
    head = "".join(cell("th", i, c) for i, c in enumerate(columns))
    body = "".join("<tr>" + "".join(cell("td", i, v) for i, v in enumerate(row)) + "</tr>\n" for row in rows)
    cap = f"<caption>{escape(caption)}</caption>" if caption else ""
    return f"<table>{cap}<thead><tr>{head}</tr></thead>\n<tbody>\n{body}</tbody></table>\n"


def _marked(text: str) -> str:
    """``text`` escaped, with :data:`REFUSED` shown as a refusal."""
    return escape(text).replace(REFUSED, f'<strong class="refused">{REFUSED}</strong>')


def word_lines(lines: Iterable[str]) -> str:
    """Lines of a text report as paragraphs: ``WARNING`` lines as warnings, ``note:`` lines as notes,
    ``Verdict:`` in bold, indented lines as sub-items."""
    out = []
    for line in lines:
        if not line.strip():
            continue
        text = line.strip()
        if text.startswith("WARNING"):
            head, _, rest = text.partition(":")
            out.append(f'<p class="warning"><strong>{escape(head)}</strong>: {_marked(rest.strip())}</p>')
        elif text.startswith("note:"):
            out.append(f'<p class="note">{_marked(text)}</p>')
        elif text.startswith("Verdict:"):
            out.append(f'<p><strong>Verdict:</strong> {_marked(text[len("Verdict:"):].strip())}</p>')
        elif line[:1].isspace():
            out.append(f'<p class="sub">{_marked(text)}</p>')
        else:
            out.append(f"<p>{_marked(text)}</p>")
    return "\n".join(out) + "\n"


def warnings_list(warnings: Iterable[str], run: str | None = None) -> str:
    """Every warning as a prominent item (empty string when there is none)."""
    items = [f'<li class="warning"><strong>WARNING{escape(f" ({run})") if run else ""}</strong>: '
             f"{_marked(w)}</li>" for w in warnings]
    return f'<ul class="warnings">{"".join(items)}</ul>\n' if items else ""


def summary(headline: str, body: str) -> str:
    """A result's compact summary: its ``headline`` (text) over ``body`` (HTML made here), in a block
    that carries its own style (a notebook shows it as the page does)."""
    return (f'<div class="momentid-summary"><style>{SUMMARY_CSS}</style>\n'
            f'<p class="headline">{_marked(headline)}</p>\n{body}</div>\n')


def matrix_table(X: Sequence[Sequence[float]] | np.ndarray, S: Sequence[Sequence[float]] | np.ndarray | None = None,
                 *, caption: str, digits: int = 4) -> str:
    """A matrix (rows: floor 1 first) as a table, each entry ``x ± s`` (4 significant digits; the standard
    error's 2) when ``S`` (same shape) is given."""
    rows = []
    for i, row in enumerate(X):
        cells = [f"{x:.{digits}g}" if S is None or not math.isfinite(float(S[i][k]))
                 else f"{x:.{digits}g} ± {S[i][k]:.2g}" for k, x in enumerate(row)]
        rows.append([f"floor {i + 1}", *cells])
    return table(["", *(f"floor {k + 1}" for k in range(len(X)))], rows, caption=caption)
