"""The run's PNGs are report.html's SVG drawings rasterised (Pillow): sizes, colours, text."""
import numpy as np
import pytest

from millflow.report import raster
from millflow.report.html import COLORS, line_plot

pytestmark = pytest.mark.skipif(not raster.available(), reason="Pillow with FreeType not installed")


def _pixels(path):
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB")).astype(int)


def test_line_plot_png_has_the_svgs_size_lines_and_text(tmp_path):
    svg = line_plot([("a &amp; b", [1, 10, 100], [0, 50, 100]), ("c", [1, 100], [100, 0])],
                    xlabel="size [um]", ylabel="passing [%]", ylim=(0, 100))
    path = tmp_path / "p.png"
    raster.svg_to_png(svg, path, scale=1.0)
    px = _pixels(path)
    assert px.shape == (380, 760, 3)  # the SVG's viewBox at one pixel per unit
    for hexcolor in COLORS[:2]:  # both series drawn in their colours
        rgb = np.array([int(hexcolor[k:k + 2], 16) for k in (1, 3, 5)])
        assert (np.abs(px - rgb).sum(axis=2) < 60).sum() > 100
    dark = (px.sum(axis=2) < 384).sum()  # text (#222, anti-aliased): dark ink beyond the lines
    assert dark > 300


def test_html_entities_and_rotation_are_drawn(tmp_path):
    svg = ('<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 -20 200 120" width="200" height="120">'
           '<text x="100" y="-5" text-anchor="middle" class="ttl">P80 &middot; 1&nbsp;mm &lt; 2</text>'
           '<text transform="translate(16 50) rotate(-90)" text-anchor="middle">up</text>'
           '<polyline points="40,50 180,50" stroke="#303030" stroke-width="1.4" marker-end="url(#arr)"/>'
           '<rect x="60" y="70" width="80" height="20" rx="3" class="unit"/></svg>')
    path = tmp_path / "d.png"
    raster.svg_to_png(svg, path, scale=1.0)
    px = _pixels(path)
    assert px.shape == (120, 200, 3)
    assert (px[:20].sum(axis=2) < 384).any()  # the title in the band above y = 0 (rows 0-19)
    assert (px[50:90, :25].sum(axis=2) < 384).any()  # the rotated label left of x = 16 around y = 50 (row 70)
    line_rows = (px[:, 60:150].sum(axis=2) < 384).sum(axis=1)
    assert line_rows[70] > 80  # the stream at y = 50
    head = (px[60:81, 170:180].sum(axis=2) < 384).sum(axis=0)  # 7 stroke widths long, 10 wide
    assert head[0] > head[-1] >= 1  # the arrow head narrows to its tip at x = 180
