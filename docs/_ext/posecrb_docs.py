"""Sphinx helpers of the posecrb documentation.

``<a id="name"></a>`` anchors in a markdown page (docs/design.md keeps its anchors stable this way,
and the code's comments point at them) become link targets, so ``[text](#name)`` resolves in the
site as it does on a repository browser.

``posecrb-api`` expands, in place, to one autodoc entry for every name in ``posecrb.__all__`` (in
that order), so the API reference lists exactly the public API and cannot drift from it: a name
added to ``__all__`` appears at the next build, a removed one disappears.
"""
from __future__ import annotations

import inspect
import re
from typing import Any

from docutils import nodes
from docutils.statemachine import StringList
from docutils.transforms import Transform
from sphinx.application import Sphinx
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


def setup(app: Sphinx) -> dict[str, Any]:
    app.add_directive("posecrb-api", PublicApi)
    app.add_transform(HtmlAnchors)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
