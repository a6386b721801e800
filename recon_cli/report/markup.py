"""HTML building blocks: escaped text, relative links, tables, figures and the page shell.

Text is escaped where it enters (:func:`esc`); :class:`Html` marks a fragment that is HTML
already, so nothing is escaped twice and nothing raw slips through. Links are relative to
the page's folder and percent-encoded, so a run folder can be moved, zipped and mailed.
"""

from __future__ import annotations

import html
import os
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from urllib.parse import quote


class Html(str):
    """A fragment of HTML (not escaped again)."""


Content = str | Html | None


def esc(value: Content) -> Html:
    if value is None:
        return Html("")
    return value if isinstance(value, Html) else Html(html.escape(str(value), quote=True))


def join(parts: Iterable[Content], sep: str = "") -> Html:
    return Html(sep.join(esc(p) for p in parts))


def tag(name: str, content: Content | Sequence[Content] = None, **attrs: str | None) -> Html:
    """``<name attrs>content</name>``; attribute names: a trailing ``_`` is dropped (``class_``)."""
    text = "".join(f' {k.rstrip("_").replace("_", "-")}="{html.escape(str(v), quote=True)}"'
                   for k, v in attrs.items() if v is not None)
    body = esc(content) if content is None or isinstance(content, str) else join(content)
    return Html(f"<{name}{text}>{body}</{name}>")


def href(target: Path, page_dir: Path) -> str:
    """The relative, percent-encoded link from a page in ``page_dir`` to ``target``."""
    rel = os.path.relpath(Path(target).absolute(), Path(page_dir).absolute())
    return quote(Path(rel).as_posix())


def link(target: Path, page_dir: Path, text: Content = None) -> Html:
    return tag("a", text if text is not None else Path(target).name, href=href(target, page_dir))


def image(target: Path, page_dir: Path, alt: str, width: int | None = None) -> Html:
    w = f' width="{int(width)}"' if width else ""
    return Html(f'<img src="{html.escape(href(target, page_dir))}" alt="{html.escape(alt)}"{w} loading="lazy">')


def figure(target: Path, page_dir: Path, caption: Content, width: int | None = None) -> Html:
    """A picture (linked to its full size) with its caption."""
    picture = tag("a", image(target, page_dir, str(caption or Path(target).name), width), href=href(target, page_dir))
    return tag("figure", [picture, tag("figcaption", caption)])


def table(head: Sequence[str], rows: Iterable[Sequence[Content]], numeric: Iterable[int] = (),
          class_: str | None = None) -> Html:
    """A table; columns listed in ``numeric`` are right-aligned."""
    right = set(numeric)

    def cell(name: str, k: int, value: Content) -> Html:
        return tag(name, value, class_="num" if k in right else None)

    thead = tag("thead", tag("tr", [cell("th", k, h) for k, h in enumerate(head)]))
    body = [tag("tr", [cell("td", k, v) for k, v in enumerate(row)]) for row in rows]
    return tag("table", [thead, tag("tbody", body)], class_=class_)


def facts(rows: Iterable[tuple[str, Content]]) -> Html:
    """A two-column table of labels and values (rows with a None value are left out)."""
    body = [tag("tr", [tag("th", label), tag("td", value)]) for label, value in rows if value is not None]
    return tag("table", tag("tbody", body), class_="facts")


def section(ident: str, title: str, *content: Content) -> Html:
    return tag("section", [tag("h2", title), *content], id=ident)


def note(text: Content) -> Html:
    return tag("p", text, class_="note")


def num(value: float | int | None, fmt: str = ".3g", unit: str = "") -> str | None:
    """``value`` formatted with its unit; None stays None (left out / shown empty)."""
    if value is None:
        return None
    text = f"{value:d}" if isinstance(value, int) and not isinstance(value, bool) else format(value, fmt)
    return f"{text} {unit}".rstrip()


def pct(share: float | None, digits: int = 1) -> str | None:
    return None if share is None else f"{100 * share:.{digits}f} %"


def size(n_bytes: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n_bytes < 1000 or unit == "GB":
            return f"{n_bytes:.0f} {unit}" if unit == "B" else f"{n_bytes:.1f} {unit}"
        n_bytes /= 1000
    return f"{n_bytes:.1f} GB"


STATUS_CLASS = {"done": "ok", "passed": "ok", "failed": "bad", "aborted": "bad", "timeout": "bad", "error": "warn",
                "interrupted": "warn", "skipped": "warn", "planned": "ok", "recorded": "ok", "not run": "warn"}


def status(text: str) -> Html:
    return tag("span", text, class_=f"status {STATUS_CLASS.get(text, 'warn')}")


GENERATOR = "recon report"  # marks a page recon wrote (and may write again)

CSS = """
body { font: 14px/1.45 system-ui, -apple-system, "Segoe UI", sans-serif; margin: 0 auto; max-width: 1200px;
       padding: 0 1.5em 3em; color: #222; }
header { border-bottom: 1px solid #ccc; margin-bottom: 1em; }
h1 { font-size: 1.5em; margin: 0.8em 0 0.2em; } h2 { font-size: 1.2em; margin-top: 1.6em; }
nav a { margin-right: 1em; } .meta { color: #666; }
table { border-collapse: collapse; margin: 0.5em 0; } th, td { padding: 0.2em 0.6em; border-bottom: 1px solid #e4e4e4;
  text-align: left; vertical-align: top; } thead th { border-bottom: 2px solid #bbb; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; } table.facts th { font-weight: 600; }
.status { padding: 0.05em 0.5em; border-radius: 0.6em; font-weight: 600; }
.ok { background: #dff3df; color: #185b18; } .bad { background: #fadddd; color: #8a1414; }
.warn { background: #fff1cc; color: #6b4b00; }
.gallery { display: flex; flex-wrap: wrap; gap: 1em; } figure { margin: 0; }
figure img { max-width: 100%; border: 1px solid #ddd; } figcaption { color: #555; font-size: 0.9em; }
.note { color: #6b4b00; } code { background: #f4f4f4; padding: 0 0.2em; }
"""


def page(title: str, subtitle: Content, nav: Sequence[tuple[str, str]], body: Sequence[Content]) -> str:
    """The whole document: one page, its style inline, nothing fetched from elsewhere."""
    links = tag("nav", [tag("a", text, href=f"#{ident}") for ident, text in nav])
    stamp = time.strftime("%Y-%m-%d %H:%M:%S")
    head = ('<head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">'
            f'<meta name="generator" content="{GENERATOR}">'
            f"{tag('title', title)}<style>{CSS}</style></head>")
    header = tag("header", [tag("h1", title), tag("p", subtitle, class_="meta"), links])
    footer = tag("footer", tag("p", f"written by recon on {stamp}", class_="meta"))
    return f'<!DOCTYPE html>\n<html lang="en">{head}<body>{header}{join(body)}{footer}</body></html>\n'
