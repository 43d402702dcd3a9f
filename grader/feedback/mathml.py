"""TeX as MathML, written when the page is written: browsers typeset MathML themselves, so a
feedback page loads no MathJax (nothing from a CDN)."""

from __future__ import annotations

import functools
import html
import re

_MATH = re.compile(r"\$\$(.+?)\$\$|\\\[(.+?)\\\]|\$(.+?)\$|\\\((.+?)\\\)", re.S)


@functools.lru_cache(maxsize=4096)
def tex_to_mathml(tex: str, display: bool = False) -> str:
    """TeX as a MathML element (browsers typeset MathML without any script); on TeX it cannot
    read, the TeX itself in a ``<code>``.

    >>> tex_to_mathml("q_1")
    '<math display="inline"><mrow><msub><mi>q</mi><mn>1</mn></msub></mrow></math>'
    """
    from latex2mathml.converter import convert

    clean = re.sub(r"\\\\\[[^\]]*\]", r"\\\\", tex.strip())  # a row break's extra space (\\[2mm]) is not MathML's
    try:
        out = convert(clean, display="block" if display else "inline")
    except Exception:  # noqa: BLE001 - anything latex2mathml cannot read stays readable TeX
        return f"<code class='grader-tex'>{html.escape(tex)}</code>"
    return out.replace(' xmlns="http://www.w3.org/1998/Math/MathML"', "")


def math_html(latex: str) -> str:
    """A ``text/latex`` output (``$...$``, ``$$...$$``, ``\\[...\\]``) as HTML with MathML."""
    parts, last = [], 0
    for m in _MATH.finditer(latex):
        parts.append(html.escape(latex[last:m.start()]))
        block = m.group(1) is not None or m.group(2) is not None
        parts.append(tex_to_mathml(next(g for g in m.groups() if g is not None), block))
        last = m.end()
    if not parts:
        return tex_to_mathml(latex, True)
    parts.append(html.escape(latex[last:]))
    return "".join(parts)

