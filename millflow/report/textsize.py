"""How wide a line of text is drawn, and long names broken onto lines that fit.

The boxes of a flowsheet drawing are sized from their text, not fixed: a width per
character from the advance widths of DejaVu Sans (regular and bold, the font the
drawing asks for first, and the widest of the common sans-serif faces: Arial, Helvetica,
Segoe UI and Roboto set the same text narrower), times :data:`MARGIN`. Characters
outside printable ASCII count one em (the widest ASCII glyph, "@", is one em).
Text with HTML entities (``&#177;``) is measured as it is shown.
"""
from __future__ import annotations

import html

__all__ = ["FONT_PX", "LINE_H", "Strong", "text_width", "box_size", "name_lines"]

#: Font size of the drawing's text [px] and the height of one line of it [px].
FONT_PX, LINE_H = 12.0, 15.0
#: Head-room on the measured widths, for faces slightly wider than DejaVu Sans (Verdana).
MARGIN = 1.04

# advance widths [em] of DejaVu Sans 2.37 (matplotlib's copy), ASCII 32..126
_REGULAR = (
    0.318, 0.401, 0.46, 0.838, 0.636, 0.95, 0.78, 0.275, 0.39, 0.39, 0.5, 0.838, 0.318, 0.361, 0.318, 0.337,
    0.636, 0.636, 0.636, 0.636, 0.636, 0.636, 0.636, 0.636, 0.636, 0.636, 0.337, 0.337, 0.838, 0.838, 0.838, 0.531,
    1.0, 0.684, 0.686, 0.698, 0.77, 0.632, 0.575, 0.775, 0.752, 0.295, 0.295, 0.656, 0.557, 0.863, 0.748, 0.787,
    0.603, 0.787, 0.695, 0.635, 0.611, 0.732, 0.684, 0.989, 0.685, 0.611, 0.685, 0.39, 0.337, 0.39, 0.838, 0.5,
    0.5, 0.613, 0.635, 0.55, 0.635, 0.615, 0.352, 0.635, 0.634, 0.278, 0.278, 0.579, 0.278, 0.974, 0.634, 0.612,
    0.635, 0.635, 0.411, 0.521, 0.392, 0.634, 0.592, 0.818, 0.592, 0.592, 0.525, 0.636, 0.337, 0.636, 0.838)
_BOLD = (
    0.348, 0.456, 0.521, 0.838, 0.696, 1.002, 0.872, 0.306, 0.457, 0.457, 0.523, 0.838, 0.38, 0.415, 0.38, 0.365,
    0.696, 0.696, 0.696, 0.696, 0.696, 0.696, 0.696, 0.696, 0.696, 0.696, 0.4, 0.4, 0.838, 0.838, 0.838, 0.58,
    1.0, 0.774, 0.762, 0.734, 0.83, 0.683, 0.683, 0.821, 0.837, 0.372, 0.372, 0.775, 0.637, 0.995, 0.837, 0.85,
    0.733, 0.85, 0.77, 0.72, 0.682, 0.812, 0.774, 1.103, 0.771, 0.724, 0.725, 0.457, 0.365, 0.457, 0.838, 0.5,
    0.5, 0.675, 0.716, 0.593, 0.716, 0.678, 0.435, 0.716, 0.712, 0.343, 0.343, 0.665, 0.343, 1.042, 0.712, 0.687,
    0.716, 0.716, 0.493, 0.595, 0.478, 0.712, 0.652, 0.924, 0.645, 0.652, 0.582, 0.712, 0.365, 0.712, 0.838)


class Strong(str):
    """A line of a box drawn in bold (the first line of a box is bold anyway)."""


def text_width(text: str, font_px: float = FONT_PX, *, bold: bool = False, escaped: bool = True) -> float:
    """Width [px] of one line of text in the drawing's font.

    Width [px] of one line of ``text`` in the drawing's font at ``font_px``
    (``escaped``: the text holds HTML entities, measured as shown).
    """
    if escaped:
        text = html.unescape(text)
    table = _BOLD if bold else _REGULAR
    em = sum(table[ord(c) - 32] if 32 <= ord(c) < 127 else 1.1 if bold else 1.0 for c in text)
    return em * font_px * MARGIN


def box_size(lines, font_px: float = FONT_PX, *, pad_x: float = 8.0, pad_y: float = 3.0,
             min_w: float = 0.0, min_h: float = 0.0) -> tuple[float, float]:
    """Width and height [px] of a box holding lines of text.

    (width, height) [px] of a box holding ``lines`` (text, or (text, key) pairs; the
    first line and :class:`Strong` lines bold), with ``pad_x`` and ``pad_y`` of room on
    each side.
    """
    texts = [line[0] if isinstance(line, tuple) else line for line in lines]
    w = max((text_width(t, font_px, bold=k == 0 or isinstance(t, Strong)) for k, t in enumerate(texts)),
            default=0.0) + 2 * pad_x
    h = LINE_H * font_px / FONT_PX * len(texts) + 2 * pad_y
    return max(w, min_w), max(h, min_h)


def name_lines(name: str, max_px: float = 190.0, font_px: float = FONT_PX, max_lines: int = 2) -> list[str]:
    """A name broken into at most ``max_lines`` lines of at most ``max_px``.

    ``name`` (plain text) as at most ``max_lines`` lines of at most ``max_px`` in bold:
    broken after ``_``, ``-``, ``.``, ``/`` or a space where it can be, inside a word where
    it cannot, and the last line ended with an ellipsis when the name is longer still
    (the drawing then gives the whole name as the box's tooltip).
    """
    def fits(s):
        return text_width(s, font_px, bold=True, escaped=False) <= max_px

    lines, rest = [], name
    while rest and len(lines) < max_lines:
        if fits(rest):
            lines.append(rest)
            rest = ""
            break
        cut = 1
        while cut < len(rest) and fits(rest[:cut + 1]):
            cut += 1
        breaks = [k + 1 for k in range(cut) if rest[k] in "_-./ "]
        if breaks and breaks[-1] >= cut // 2:  # a separator in the second half of what fits
            cut = breaks[-1]
        lines.append(rest[:cut].rstrip())
        rest = rest[cut:].lstrip()
    if rest:
        last = lines[-1]
        while last and not fits(last + "\u2026"):
            last = last[:-1]
        lines[-1] = last + "\u2026"
    return lines or [""]
