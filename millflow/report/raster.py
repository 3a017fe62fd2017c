"""PNG images of the report's SVG drawings, rasterised with Pillow.

report.html draws its plots and the flowsheet as SVG (:func:`millflow.report.html.line_plot`,
:func:`~millflow.report.html.flowsheet_svg`). A run's PNGs are the same drawings: this
module paints the small subset of SVG those functions write (``rect``, ``line``,
``polyline`` with an arrow head at ``marker-end``, ``text`` with ``text-anchor``, bold
classes and a -90 degree rotation, the page's CSS classes as fixed styles) onto a
Pillow image at twice the size and reduces it (smooth lines and text without a
drawing library). It costs a few hundredths of a second where matplotlib's import
alone took about half a second of every run. :func:`available` says whether Pillow
with FreeType (scalable text) is installed; without it millflow draws the PNGs with
matplotlib, as before.
"""
from __future__ import annotations

import html
import math
import re
import xml.etree.ElementTree as ET

__all__ = ["available", "svg_to_png"]

_NS = "{http://www.w3.org/2000/svg}"
#: The page's CSS for the drawings (millflow.report.html), as fixed styles: class ->
#: (fill, stroke, stroke width); None: not painted.
_STYLE = {
    "frame": (None, "#888888", 1.0),
    "grid": (None, "#e4e4e4", 1.0),
    "stream": (None, "#303030", 1.4),
    "recycle": (None, "#a03030", 1.4),
    "unit": ("#e8f0fa", "#3060a0", 1.5),
    "stream-label": ("#ffffff", "#bbbbbb", 1.0),
}
_TEXT = "#222222"
_FONT_PX = 12.0  # svg{font-size:12px}
_SUPER = 2  # drawn at twice the size, then reduced: anti-aliased lines and text


def available() -> bool:
    """True when Pillow with FreeType (scalable fonts) is installed."""
    try:
        from PIL import features
    except ImportError:
        return False
    return bool(features.check("freetype2"))


def svg_to_png(svg: str, path, scale: float = 1.25) -> None:
    """Write the SVG drawing ``svg`` (as the report's drawing functions write it) to the
    PNG ``path``, ``scale`` pixels per SVG unit."""
    from PIL import Image, ImageDraw

    root = ET.fromstring(_xml_entities(svg))
    x0, y0, w, h = (float(v) for v in root.get("viewBox").split())
    k = scale * _SUPER
    image = Image.new("RGB", (max(1, round(w * k)), max(1, round(h * k))), "white")
    painter = _Painter(image, ImageDraw.Draw(image), k, x0, y0)
    painter.walk(root, ())
    image = image.resize((max(1, round(w * scale)), max(1, round(h * scale))), Image.LANCZOS)
    image.save(path, compress_level=1)


def _xml_entities(text: str) -> str:
    """HTML's named entities (&middot;, &nbsp;, ...) as numeric references XML reads."""
    keep = {"amp", "lt", "gt", "quot", "apos"}
    return re.sub(r"&([A-Za-z][A-Za-z0-9]*);",
                  lambda m: m.group(0) if m.group(1) in keep else
                  "".join(f"&#{ord(c)};" for c in html.unescape(m.group(0))), text)


class _Painter:
    def __init__(self, image, draw, k, x0=0.0, y0=0.0):
        self.image, self.draw, self.k = image, draw, k
        self.x0, self.y0 = x0, y0  # the viewBox's origin
        self._fonts = {}

    def xy(self, x, y) -> tuple:
        """Image pixels of SVG coordinates."""
        return (float(x) - self.x0) * self.k, (float(y) - self.y0) * self.k

    def font(self, bold: bool):
        from PIL import ImageFont

        if bold not in self._fonts:
            self._fonts[bold] = ImageFont.load_default(size=_FONT_PX * self.k)
        return self._fonts[bold]

    def walk(self, node, classes: tuple) -> None:
        tag = node.tag.replace(_NS, "")
        if tag == "defs":
            return
        cls = tuple((node.get("class") or "").split())
        classes = classes + cls
        paint = getattr(self, f"_{tag}", None)
        if paint is not None:
            paint(node, classes)
        for child in node:
            self.walk(child, classes)

    def _style(self, node, classes):
        fill, stroke, width = None, None, 1.0
        for c in classes:
            if c in _STYLE:
                fill, stroke, width = _STYLE[c]
        fill = node.get("fill", fill)
        stroke = node.get("stroke", stroke)
        width = float(node.get("stroke-width", width))
        return (None if fill in (None, "none") else fill), (None if stroke in (None, "none") else stroke), width

    def _rect(self, node, classes):
        fill, stroke, width = self._style(node, classes)
        k = self.k
        x, y = self.xy(node.get("x", 0), node.get("y", 0))
        box = (x, y, x + float(node.get("width")) * k, y + float(node.get("height")) * k)
        self.draw.rounded_rectangle(box, radius=float(node.get("rx", 0)) * k, fill=fill, outline=stroke,
                                    width=max(1, round(width * k)))

    def _line(self, node, classes):
        _, stroke, width = self._style(node, classes)
        if stroke:
            pts = [self.xy(node.get("x1"), node.get("y1")), self.xy(node.get("x2"), node.get("y2"))]
            self.draw.line(pts, fill=stroke, width=max(1, round(width * self.k)))

    def _polyline(self, node, classes):
        _, stroke, width = self._style(node, classes)
        k = self.k
        pts = [self.xy(a, b) for a, b in (p.split(",") for p in node.get("points").split())]
        if not stroke or len(pts) < 2:
            return
        self.draw.line(pts, fill=stroke, width=max(1, round(width * k)), joint="curve")
        if node.get("marker-end"):  # the report's arrow: 7 stroke widths long and wide, tip at the end
            (x0, y0), (x1, y1) = pts[-2], pts[-1]
            d = math.hypot(x1 - x0, y1 - y0) or 1.0
            ux, uy = (x1 - x0) / d, (y1 - y0) / d
            size = 7 * width * k
            base = (x1 - ux * size, y1 - uy * size)
            self.draw.polygon([(x1, y1), (base[0] - uy * size / 2, base[1] + ux * size / 2),
                               (base[0] + uy * size / 2, base[1] - ux * size / 2)], fill=stroke)

    def _text(self, node, classes):
        text = "".join(node.itertext())
        if not text:
            return
        k = self.k
        bold = "b" in classes or "ttl" in classes
        font = self.font(bold)
        anchor = {"middle": "ms", "end": "rs"}.get(node.get("text-anchor"), "ls")
        stroke = max(1, round(0.35 * k)) if bold else 0  # a bold face drawn by a thin outline
        transform = node.get("transform")
        if transform and "rotate(-90)" in transform:
            tx, ty = re.search(r"translate\(([-\d.]+)[ ,]+([-\d.]+)\)", transform).groups()
            self._rotated(text, font, *self.xy(tx, ty), anchor, stroke)
            return
        x, y = self.xy(node.get("x", 0), node.get("y", 0))
        self.draw.text((x, y), text, fill=_TEXT, font=font, anchor=anchor, stroke_width=stroke, stroke_fill=_TEXT)

    def _rotated(self, text, font, x, y, anchor, stroke):
        from PIL import Image, ImageDraw

        left, top, right, bottom = font.getbbox(text, anchor="ls", stroke_width=stroke)
        tile = Image.new("L", (right - left + 2, bottom - top + 2), 0)
        ImageDraw.Draw(tile).text((1 - left, 1 - top), text, fill=255, font=font, anchor="ls", stroke_width=stroke,
                                  stroke_fill=255)
        tile = tile.rotate(90, expand=True)
        # baseline vertical at x (the text reads upwards), centred on y for "middle"
        width, height = tile.size
        top_y = y - height / 2 if anchor == "ms" else (y - height if anchor == "ls" else y)
        ink = Image.new("RGB", tile.size, _TEXT)
        self.image.paste(ink, (round(x + top), round(top_y)), tile)
