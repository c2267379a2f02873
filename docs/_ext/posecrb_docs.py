"""Sphinx helpers of the posecrb documentation.

``<a id="name"></a>`` anchors in a markdown page (docs/design.md keeps its anchors stable this way,
and the code's comments point at them) become link targets, so ``[text](#name)`` resolves in the
site as it does on a repository browser.

``posecrb-api`` expands, in place, to one autodoc entry for every name in ``posecrb.__all__`` (in
that order), so the API reference lists exactly the public API and cannot drift from it: a name
added to ``__all__`` appears at the next build, a removed one disappears.

A mention of a documentation page in plain text, ``docs/design.md#timeline`` (docstrings and
``--help`` texts name pages that way, since a terminal has no links), becomes a link to that page
and anchor in the site.

The one sidebar (conf.py) shows the section's pages and the page's contents; a page outside any
section, or without sections of its own, gets only what it has, so no sidebar is an empty heading.

Every figure links to its full-size image.

A code block that prints a table (box drawing, or markdown's pipes) gets the class
``posecrb-table``, and ``posecrb-wide`` when its rows need a smaller font to fit the column: the
site's CSS (docs/_static/posecrb.css) wraps the long lines of other blocks, and keeps a table's
columns aligned.
"""
from __future__ import annotations

import inspect
import re
from typing import Any

from docutils import nodes
from docutils.statemachine import StringList
from docutils.transforms import Transform
from sphinx.application import Sphinx
from sphinx.transforms.post_transforms import SphinxPostTransform
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles

import posecrb  # conf.py puts the checkout first on sys.path


def public_api() -> list[tuple[str, str]]:
    """``(name, autodoc directive)`` for every name in ``posecrb.__all__``."""
    entries = []
    for name in posecrb.__all__:
        obj = getattr(posecrb, name)
        if inspect.isclass(obj):
            kind = "exception" if issubclass(obj, BaseException) else "class"
        elif inspect.isroutine(obj):
            kind = "function"
        elif inspect.ismodule(obj):
            kind = "module"
        else:
            kind = "data"
        entries.append((name, kind))
    return entries


class PublicApi(SphinxDirective):
    """Autodoc entries for ``posecrb.__all__``."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        lines = [".. currentmodule:: posecrb", ""]
        for name, kind in public_api():
            if kind == "module":
                lines += [f".. automodule:: posecrb.{name}", ""]
            elif kind in ("class", "exception"):
                lines += [f".. auto{kind}:: {name}", "   :members:", "   :show-inheritance:", ""]
            else:
                lines += [f".. auto{kind}:: {name}", ""]
        container = nodes.section()
        container.document = self.state.document
        nested_parse_with_titles(self.state, StringList(lines, source="posecrb.__all__"), container)
        return container.children


_HTML_ANCHOR = re.compile(r'\s*<a id="([A-Za-z0-9_-]+)">(</a>)?\s*')


class HtmlAnchors(Transform):
    """Replace each raw ``<a id="name"></a>`` by an explicit target of that name (before MyST
    resolves ``#name`` links; other pages' ``page.md#name`` links find it among the labels)."""

    default_priority = 700

    def apply(self, **kwargs: Any) -> None:
        for raw in list(self.document.findall(nodes.raw)):
            m = _HTML_ANCHOR.fullmatch(raw.astext())
            if not m or "html" not in raw.get("format", "").split():
                continue
            closing = raw.next_node(descend=False, siblings=True)
            if not m[2] and isinstance(closing, nodes.raw) and closing.astext().strip() == "</a>":
                closing.parent.remove(closing)     # MyST parses the inline tag pair as two raw nodes
            if m[1] in self.document.ids:          # the heading's own anchor has that name already
                raw.parent.remove(raw)
                continue
            target = nodes.target("", "", ids=[m[1]], names=[m[1]])
            # explicit: ``page.md#name`` links from other pages resolve through Sphinx's labels
            self.document.note_explicit_target(target, target)
            raw.replace_self(target)


_DOCS_PATH = re.compile(r"\bdocs/((?:[A-Za-z0-9_-]+/)*[A-Za-z0-9_-]+)\.md(?:#([A-Za-z0-9_-]+))?")
_NO_LINKS = (nodes.literal, nodes.literal_block, nodes.reference, nodes.raw, nodes.comment)


class DocsPathLinks(SphinxPostTransform):
    """Turn ``docs/<page>.md[#anchor]`` in running text into a link to that page of the site."""

    default_priority = 5            # after references are resolved: these are finished links
    formats = ("html",)

    def run(self, **kwargs: Any) -> None:
        for text in list(self.document.findall(nodes.Text)):
            if not _DOCS_PATH.search(text) or any(isinstance(a, _NO_LINKS) for a in _ancestors(text)):
                continue
            pieces: list[nodes.Node] = []
            pos = 0
            for m in _DOCS_PATH.finditer(text):
                if m[1] not in self.env.all_docs:
                    continue
                uri = self.app.builder.get_relative_uri(self.env.docname, m[1])
                if m[2]:
                    uri = f"{uri.split('#')[0]}#{m[2]}"
                pieces += [nodes.Text(text[pos:m.start()]),
                           nodes.reference(m[0], m[0], refuri=uri, internal=True)]
                pos = m.end()
            if pieces:
                text.parent.replace(text, [*pieces, nodes.Text(text[pos:])])


def _ancestors(node: nodes.Node) -> list[nodes.Node]:
    out = []
    while node.parent is not None:
        node = node.parent
        out.append(node)
    return out


_TABLE_ROW = re.compile(r"^\s*(?:[┏┃┡┗│└┌├╭╰]|\|)|\s\|\s|-{3}\|")
# Characters of code per line in the content column at a 1400 px window (a 15 px scrollbar
# included): 122 at the theme's code font (14 px), 148 at the smaller font of wide tables
# (0.72rem); measured in Chromium. The limits keep a margin.
TABLE_CHARS = 120
WIDE_TABLE_CHARS = 145


def table_rows(text: str) -> list[str]:
    """The lines of a code block that belong to a printed table (box drawing or markdown pipes;
    a ``$`` command line is not one, whatever it pipes through)."""
    return [ln for ln in text.splitlines() if not ln.startswith("$ ") and _TABLE_ROW.search(ln)]


class CodeTables(Transform):
    """Class ``posecrb-table`` on code blocks that print a table: below a 1400 px window their
    lines do not wrap, so that the columns stay aligned (the block scrolls instead). A table whose
    rows are longer than the column holds at the normal font also gets ``posecrb-wide``, a
    smaller font."""

    default_priority = 800

    def apply(self, **kwargs: Any) -> None:
        for block in self.document.findall(nodes.literal_block):
            rows = table_rows(block.astext())
            if rows:
                block["classes"].append("posecrb-table")
                if max(map(len, rows)) > TABLE_CHARS:
                    block["classes"].append("posecrb-wide")


class FullSizeFigures(Transform):
    """Every figure links to its full-size image (Sphinx does so for an image with a scale): a
    figure shrunk to a narrow column opens at its own size, legend readable, on a click."""

    default_priority = 800

    def apply(self, **kwargs: Any) -> None:
        for image in self.document.findall(nodes.image):
            sized = {"scale", "width", "height"} & set(image.attributes)
            if not sized and not isinstance(image.parent, nodes.reference):
                image["scale"] = 100


def drop_empty_sidebars(app: Sphinx, pagename: str, templatename: str, context: dict[str, Any],
                        doctree: nodes.document | None) -> None:
    """Drop the section navigation of a page that has no section (a top-level page without
    sub-pages), and the contents of a page without sections, from the sidebar."""
    sidebars = context.get("sidebars")
    if not sidebars:
        return
    env = app.env
    top_level = pagename in env.toctree_includes.get(app.config.root_doc, [])
    in_section = not top_level and pagename != app.config.root_doc
    drop = set()
    if not (in_section or env.toctree_includes.get(pagename)):
        drop.add("sidebar-nav-bs")
    if doctree is None or not any(isinstance(s.parent, nodes.section) for s in doctree.findall(nodes.section)):
        drop.add("page-toc")
    context["sidebars"] = [s for s in sidebars if s.removesuffix(".html") not in drop]


def setup(app: Sphinx) -> dict[str, Any]:
    app.connect("html-page-context", drop_empty_sidebars)
    app.add_directive("posecrb-api", PublicApi)
    app.add_transform(HtmlAnchors)
    app.add_transform(CodeTables)
    app.add_transform(FullSizeFigures)
    app.add_post_transform(DocsPathLinks)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
