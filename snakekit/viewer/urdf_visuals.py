"""The arm's visual boxes, read from the generated URDF (so the picture matches the description)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass


@dataclass(frozen=True)
class VisualBox:
    """One visual box of the URDF.

    Attributes:
        link: the link it belongs to (``base_link``, ``link1``...).
        name: the visual's name in the URDF.
        origin: box centre in the link frame [m].
        size: edge lengths (x, y, z) [m].
        color: RGB colour as 0xRRGGBB.
    """

    link: str
    name: str
    origin: tuple[float, float, float]
    size: tuple[float, float, float]
    color: int


def _rgb_hex(rgba: str) -> int:
    r, g, b = (min(max(float(c), 0.0), 1.0) for c in rgba.split()[:3])
    return (round(r * 255) << 16) | (round(g * 255) << 8) | round(b * 255)


def visual_boxes(urdf_text: str) -> list[VisualBox]:
    """The box visuals of a URDF, in document order.

    >>> from snakekit.model import urdf
    >>> boxes = visual_boxes(urdf())
    >>> sorted({b.link for b in boxes})
    ['base_link', 'link1', 'link2', 'link3', 'link4', 'link5']
    """
    root = ET.fromstring(urdf_text)
    colors = {m.get("name"): _rgb_hex(m.find("color").get("rgba"))
              for m in root.findall("material") if m.find("color") is not None}
    out = []
    for link in root.findall("link"):
        for vis in link.findall("visual"):
            box = vis.find("geometry/box")
            if box is None:
                continue
            origin = vis.find("origin")
            xyz = origin.get("xyz", "0 0 0") if origin is not None else "0 0 0"
            mat = vis.find("material")
            color = 0xAAAAAA
            if mat is not None:
                inline = mat.find("color")
                color = _rgb_hex(inline.get("rgba")) if inline is not None else colors.get(mat.get("name"), color)
            out.append(VisualBox(link.get("name"), vis.get("name", ""), tuple(map(float, xyz.split())),
                                 tuple(map(float, box.get("size").split())), color))
    return out


