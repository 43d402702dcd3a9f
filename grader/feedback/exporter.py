"""The feedback page: a feedback notebook as one HTML file that works offline and as it is.

It loads nothing (no require.js, MathJax or mermaid from a CDN; the math of markdown cells is
written as MathML, :mod:`grader.feedback.mathml`), the verdict cells show their output only, and
one exporter per thread keeps what every page of a class repeats (the lesson's cells).
"""

from __future__ import annotations

import functools
import re
import threading
from collections import OrderedDict
from pathlib import Path

from grader.feedback.mathml import tex_to_mathml
from grader.feedback.page import html_page

TEMPLATES = Path(__file__).resolve().parents[1] / "templates"

_exporters = threading.local()


def _memo(fn, size: int = 4096):
    """``fn`` of strings with its recent results kept (each feedback page repeats the lesson's cells)."""
    cached = functools.lru_cache(maxsize=size)(lambda args, kw: fn(*args, **dict(kw)))

    def call(*args, **kw):
        key = tuple(sorted((k, _frozen(v)) for k, v in kw.items()))
        try:
            hash((args, key))
        except TypeError:  # an argument that cannot be a key
            return fn(*args, **kw)
        return cached(args, key)
    return call


def _frozen(v):
    if isinstance(v, dict):
        return tuple(sorted((k, _frozen(x)) for k, x in v.items()))
    if isinstance(v, list | set):
        return tuple(_frozen(x) for x in v)
    return v


def exporter_config():
    """nbconvert's settings for a feedback page: the verdict cells show their output only, no prompts,
    and the page template loads nothing from the network."""
    from traitlets.config import Config

    c = Config()
    c.HTMLExporter.extra_template_basedirs = [str(TEMPLATES)]
    c.HTMLExporter.template_name = "snakekit_feedback"
    c.TagRemovePreprocessor.remove_input_tags = {"grader-verdict"}
    c.TagRemovePreprocessor.enabled = True
    c.HTMLExporter.exclude_input_prompt = True
    c.HTMLExporter.exclude_output_prompt = True
    c.HTMLExporter.optimistic_validation = True  # the notebook validated once, not after each of a dozen steps
    # a print arrives in one piece or several, as the kernel flushed it on a quiet or a busy machine:
    # merged, a page graded again is the same page
    c.CoalesceStreamsPreprocessor.enabled = True
    return c


def exporter_class():
    """nbconvert's HTML exporter, with the math of markdown cells written as MathML."""
    from jinja2 import pass_context
    from nbconvert import HTMLExporter
    from nbconvert.filters.markdown_mistune import IPythonRenderer, MarkdownWithMath

    class MathMLRenderer(IPythonRenderer):
        def block_math(self, body: str) -> str:
            return tex_to_mathml(body, True)

        def inline_math(self, body: str) -> str:
            return tex_to_mathml(body, False)

        def latex_environment(self, name: str, body: str) -> str:
            return tex_to_mathml(f"\\begin{{{name}}}{body}\\end{{{name}}}", True)

    class FeedbackPageExporter(HTMLExporter):
        @pass_context
        def markdown2html(self, context, source):
            cell = context.get("cell", {})
            attachments = cell.get("attachments", {})
            path = context.get("resources", {}).get("metadata", {}).get("path", "")
            # every page of a class repeats the lesson's text: each cell is rendered once
            key = (source, path, repr(_frozen(attachments)))
            memo = self.__dict__.setdefault("_markdown_memo", OrderedDict())
            if key in memo:
                memo.move_to_end(key)
                return memo[key]
            renderer = MathMLRenderer(
                escape=False, attachments=attachments, embed_images=self.embed_images, path=path,
                anchor_link_text=self.anchor_link_text, exclude_anchor_links=self.exclude_anchor_links,
                **self.lexer_options)
            memo[key] = out = MarkdownWithMath(renderer=renderer).render(source)
            if len(memo) > 2048:
                memo.popitem(last=False)
            return out

        def from_notebook_node(self, nb, resources=None, **kw):
            body, resources = html_page(self, nb, resources, **kw)
            # the page's style sheets credit web pages in comments; a page with no address in it is simpler to check
            return _STYLE.sub(lambda m: _CSS_COMMENT.sub(lambda c: "" if "http" in c.group(0) else c.group(0),
                                                         m.group(0)), body), resources

    return FeedbackPageExporter


_STYLE = re.compile(r"<style[^>]*>.*?</style>", re.S)
_CSS_COMMENT = re.compile(r"/\*.*?\*/", re.S)


def page_exporter():
    """One HTML exporter per thread (its templates load once; an exporter is not shared between threads).

    Every page of a class shows the same lesson text and test cells, so the exporter keeps
    the results of its per-cell filters (syntax highlighting, HTML sanitising, markdown) for reuse.
    """
    if not hasattr(_exporters, "html"):
        from nbconvert.filters.highlight import Highlight2HTML

        class FeedbackExporter(exporter_class()):
            def default_filters(self):
                for name, fn in super().default_filters():
                    yield name, (_memo(fn) if name == "clean_html" else fn)

        exporter = FeedbackExporter(config=exporter_config())
        # the feedback notebook's language is Python (build() sets it), so one highlighter serves every page
        exporter.filters = {**exporter.filters, "highlight_code": _memo(Highlight2HTML(pygments_lexer="python",
                                                                                      parent=exporter))}
        _exporters.html = exporter
    return _exporters.html


def write_html(nb, path: Path) -> Path:
    """Render the feedback notebook to one self-contained HTML file (images inline)."""
    body, _ = page_exporter().from_notebook_node(nb)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(body, encoding="utf-8")
    return path

