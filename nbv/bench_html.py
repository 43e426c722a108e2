"""report.html of ``nbv bench``: summary.md and the plots in one self-contained file.

No template engine and no Markdown library: summary.md uses a small subset (``#`` headings,
pipe tables with an alignment row, paragraphs, inline code in backticks), converted here; the
PNG plots are embedded as base64 ``data:`` URIs, so the file can be mailed or attached as is.
"""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Sequence
from pathlib import Path

STYLE = """
body { font: 14px/1.45 system-ui, sans-serif; margin: 2em auto; max-width: 1300px; color: #222; padding: 0 1em; }
h1 { font-size: 1.6em; } h2 { font-size: 1.25em; margin-top: 1.8em; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; margin: 0.6em 0; font-variant-numeric: tabular-nums; }
th, td { border: 1px solid #ccc; padding: 3px 8px; } th { background: #f3f3f3; }
td.num, th.num { text-align: right; } tr:nth-child(even) td { background: #fafafa; }
code { background: #f1f1f1; padding: 0 3px; border-radius: 3px; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #eee; }
"""


def _inline(text: str) -> str:
    """Escape ``text`` and turn `code` spans into <code>."""
    parts = re.split(r"`([^`]*)`", text)
    return "".join(f"<code>{html.escape(p)}</code>" if i % 2 else html.escape(p) for i, p in enumerate(parts))


def _cells(line: str) -> list[str]:
    inner = line.strip()[1:-1] if line.strip().endswith("|") else line.strip()[1:]
    return [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", inner)]


def markdown_to_html(text: str) -> str:
    """HTML of the Markdown subset summary.md uses (see the module docstring)."""
    out: list[str] = []
    paragraph: list[str] = []
    lines = text.splitlines()

    def flush() -> None:
        if paragraph:
            out.append(f"<p>{_inline(' '.join(paragraph))}</p>")
            paragraph.clear()

    i = 0
    while i < len(lines):
        line = lines[i]
        heading = re.match(r"^(#{1,6})\s+(.*)$", line)
        if heading:
            flush()
            level = len(heading.group(1))
            out.append(f"<h{level}>{_inline(heading.group(2))}</h{level}>")
        elif line.startswith("|") and i + 1 < len(lines) and re.match(r"^\|[\s:|-]+\|?$", lines[i + 1]):
            flush()
            header, align = _cells(line), _cells(lines[i + 1])
            numeric = [a.endswith(":") for a in align]
            row_html = "".join(
                f'<th class="num">{_inline(c)}</th>' if n else f"<th>{_inline(c)}</th>"
                for c, n in zip(header, numeric, strict=False)
            )
            rows = [f"<tr>{row_html}</tr>"]
            i += 2
            while i < len(lines) and lines[i].startswith("|"):
                cells = _cells(lines[i])
                rows.append(
                    "<tr>"
                    + "".join(
                        f'<td class="num">{_inline(c)}</td>' if n else f"<td>{_inline(c)}</td>"
                        for c, n in zip(cells, numeric, strict=False)
                    )
                    + "</tr>"
                )
                i += 1
            out.append("<table>" + "".join(rows) + "</table>")
            continue
        elif not line.strip():
            flush()
        else:
            paragraph.append(line.strip())
        i += 1
    flush()
    return "\n".join(out)


def report_html(summary_md: str, images: Sequence[Path], title: str = "nbv bench") -> str:
    """A self-contained HTML page: summary.md with the plots (inline base64 PNGs) before its timing sections."""
    body = markdown_to_html(summary_md)
    figures = []
    for path in images:
        data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
        alt = html.escape(Path(path).stem)
        figures.append(f'<figure><img alt="{alt}" src="data:image/png;base64,{data}"></figure>')
    cut = body.find("<h2>Total planning time")
    cut = len(body) if cut == -1 else cut
    page = body[:cut] + "\n<h2>Plots</h2>\n" + "\n".join(figures) + "\n" + body[cut:]
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
        f"<style>{STYLE}</style></head><body>\n{page}\n</body></html>\n"
    )
