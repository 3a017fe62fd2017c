"""Where the boxes of a flowsheet drawing go: units, stream routes and stream labels.

One layout serves the SVG of ``report.html`` and ``flowsheet.png``. Units are placed in
layers by their distance from the feeds (breadth-first), :data:`LAYERS_PER_ROW` layers to a
row (fewer for a narrow drawing), and a long circuit wraps onto further rows that run
back (boustrophedon), so a wrapped loop stays short. A stream to an earlier or the same
layer (a recycle) is routed below its row in a lane of its own, so recycle arcs never
cross the units; a route that would pass through another unit goes round it through the
corridors between the columns. Every box is sized to its text
(:mod:`millflow.report.textsize`; long names are broken onto two lines by the callers).
Each stream's label box is placed greedily at the first of a list of candidate points
along its route (a recycle's lane first) whose box overlaps no unit box and no label
placed before it, preferring among those the one that crosses the fewest other routes;
when a label finds no free place, or a route still crosses a unit, the whole layout is
made again with the spacing grown by a quarter. :func:`overlaps` and :func:`crossings`
count what is left; the tests require none for the shipped flowsheets and for seeded
random branched circuits of 20 units.

Coordinates are pixels of the drawing, y downwards (as in SVG).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from millflow.report.textsize import LINE_H, box_size

__all__ = ["Box", "FlowsheetLayout", "layout", "overlaps", "crossings", "LAYERS_PER_ROW"]

#: Layers per row of the drawing: longer circuits wrap onto further rows.
LAYERS_PER_ROW = 5
UNIT_W, UNIT_H = 136.0, 46.0
DX, DY = 340.0, 150.0  # spacing of layers and of units within a layer
LANE = 26.0  # spacing of recycle lanes below a row
LABEL_W = 168.0
MARGIN = 24.0


@dataclass(frozen=True)
class Box:
    """An axis-aligned box: centre (x, y), width w, height h [px]."""

    x: float
    y: float
    w: float
    h: float

    def overlap(self, other: "Box", pad: float = 0.0) -> float:
        """Area of the overlap of the two boxes, each grown by ``pad`` on every side."""
        dx = min(self.x + self.w / 2, other.x + other.w / 2) - max(self.x - self.w / 2, other.x - other.w / 2)
        dy = min(self.y + self.h / 2, other.y + other.h / 2) - max(self.y - self.h / 2, other.y - other.h / 2)
        dx += 2 * pad
        dy += 2 * pad
        return dx * dy if dx > 0 and dy > 0 else 0.0


@dataclass(frozen=True)
class FlowsheetLayout:
    """Unit boxes, stream routes (polylines), stream label boxes and the drawing's size [px]."""

    units: dict
    routes: dict
    labels: dict
    recycle: dict
    width: float
    height: float


def _levels(units: dict, streams: dict) -> dict:
    adj = {u: [] for u in units}
    for src, tgt in streams.values():
        adj[src].append(tgt)
    level = {u: 0 for u, kind in units.items() if kind == "feed"}
    q = deque(level)
    while q:
        u = q.popleft()
        for v in adj[u]:
            if v not in level:
                level[v] = level[u] + 1
                q.append(v)
    for u in units:
        level.setdefault(u, 0)
    return level


def _clip(box: Box, tx: float, ty: float) -> tuple[float, float]:
    """The point where the segment from the box centre towards (tx, ty) leaves the box."""
    dx, dy = tx - box.x, ty - box.y
    if dx == 0 and dy == 0:
        return box.x, box.y
    s = min(box.w / 2 / abs(dx) if dx else float("inf"), box.h / 2 / abs(dy) if dy else float("inf"))
    return box.x + s * dx, box.y + s * dy


def _point_on(route: list, t: float) -> tuple[float, float]:
    """The point at fraction ``t`` of the length of a polyline."""
    seg = [((x0, y0), (x1, y1)) for (x0, y0), (x1, y1) in zip(route[:-1], route[1:])]
    lengths = [((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5 for (x0, y0), (x1, y1) in seg]
    target = t * sum(lengths)
    for ((x0, y0), (x1, y1)), n in zip(seg, lengths):
        if target <= n and n > 0:
            f = target / n
            return x0 + f * (x1 - x0), y0 + f * (y1 - y0)
        target -= n
    return route[-1]


def layout(units: dict, streams: dict, label_lines: int = 4, *, label_text: dict | None = None,
           unit_text: dict | None = None, layers_per_row: int = LAYERS_PER_ROW) -> FlowsheetLayout:
    """Lay out a flowsheet.

    When the first placement leaves a label overlapping a box, or a route through a unit,
    the spacing grows by a quarter and the layout is made again (up to four times).

    Parameters
    ----------
    units : dict
        Unit name -> unit type (``feed``, ``mill``, ``product``, ...), in file order.
    streams : dict
        Stream name -> (source unit, target unit), in file order.
    label_lines : int
        Lines of text in each stream label, when ``label_text`` is not given (the label
        boxes are then :data:`LABEL_W` wide).
    label_text : dict, optional
        Stream name -> the lines of its label (text with HTML entities, or (text, key)
        pairs; the first line bold): each label box is sized to its text
        (:func:`millflow.report.textsize.box_size`).
    unit_text : dict, optional
        Unit name -> the lines of its box (default: name and type); a box is at least
        :data:`UNIT_W` by :data:`UNIT_H` and as large as its text.
    layers_per_row : int
        Layers of units per row before the drawing wraps (fewer: a narrower, taller drawing).
    """
    if label_text is None:
        lsize = {n: (LABEL_W, LINE_H * label_lines + 6) for n in streams}
    else:
        lsize = {n: box_size(label_text.get(n, [n])) for n in streams}
    usize = {u: box_size((unit_text or {}).get(u) or [u, str(kind)], pad_x=10.0, min_w=UNIT_W, min_h=UNIT_H)
             for u, kind in units.items()}
    lay = None
    for attempt in range(5):
        lay = _layout(units, streams, lsize, usize, layers_per_row, 1.0 + 0.25 * attempt)
        if not overlaps(lay) and not crossings(lay.units, lay.routes, streams):
            break
    return lay


def _layout(units, streams, lsize, usize, per_row, spread) -> FlowsheetLayout:
    level = _levels(units, streams)
    per_level: dict[int, list] = {}
    for u in units:
        per_level.setdefault(level[u], []).append(u)
    n_levels = max(level.values()) + 1
    n_rows = (n_levels - 1) // per_row + 1
    back = {n: level[t] <= level[s] for n, (s, t) in streams.items()}
    row_of = {u: level[u] // per_row for u in units}
    lanes_per_row = [0] * n_rows
    for n, (s, t) in streams.items():
        if back[n]:
            lanes_per_row[max(row_of[s], row_of[t])] += 1
    label_w = max([w for w, _ in lsize.values()] + [LABEL_W / 2])
    label_h = max([h for _, h in lsize.values()] + [LINE_H + 6])
    unit_w = max(w for w, _ in usize.values())
    unit_h = max(h for _, h in usize.values())
    dx = spread * max(DX, unit_w + 204.0)
    dy = spread * max(DY, unit_h + label_h + 38.0)
    lane = spread * LANE
    depth = [max((len(v) for lv, v in per_level.items() if lv // per_row == r), default=1)
             for r in range(n_rows)]
    top, row_top = MARGIN + label_h, []
    for r in range(n_rows):
        row_top.append(top)
        top += (depth[r] - 1) * dy + unit_h + 2 * lane + lane * lanes_per_row[r] + label_h + 60 * spread
    boxes = {}
    for lv, names in per_level.items():
        row, col = divmod(lv, per_row)
        if row % 2:
            col = per_row - 1 - col
        for k, u in enumerate(names):
            boxes[u] = Box(MARGIN + label_w / 2 + unit_w / 2 + col * dx, row_top[row] + unit_h / 2 + k * dy,
                           *usize[u])
    routes, lane_used = {}, [0] * n_rows
    for n, (s, t) in streams.items():
        a, b = boxes[s], boxes[t]
        if not back[n]:
            routes[n] = [_clip(a, b.x, b.y), _clip(b, a.x, a.y)]
            continue
        r = max(row_of[s], row_of[t])
        bottom = max(bx.y + bx.h / 2 for u, bx in boxes.items() if row_of[u] == r)
        lane_used[r] += 1
        y = bottom + lane * (lane_used[r] + 0.5)
        if s == t:
            routes[n] = [(a.x + a.w / 4, a.y + a.h / 2), (a.x + a.w / 4, y), (a.x - a.w / 4, y),
                         (a.x - a.w / 4, a.y + a.h / 2)]
        else:
            off = 10.0 * (1 if b.x > a.x else -1)
            routes[n] = [(a.x + off, a.y + a.h / 2), (a.x + off, y), (b.x - off, y), (b.x - off, b.y + b.h / 2)]
    _detour(boxes, routes, streams, back, dx)
    labels = _place_labels(boxes, routes, back, lsize)
    right = max(max(b.x + b.w / 2 for b in boxes.values()), max(b.x + b.w / 2 for b in labels.values()),
                max(p[0] for r in routes.values() for p in r))
    lowest = max(max(b.y + b.h / 2 for b in labels.values()), max(p[1] for r in routes.values() for p in r),
                 max(b.y + b.h / 2 for b in boxes.values()))
    left = min(min(b.x - b.w / 2 for b in labels.values()), min(p[0] for r in routes.values() for p in r), MARGIN)
    upper = min(min(b.y - b.h / 2 for b in labels.values()), MARGIN)
    shift_x, shift_y = MARGIN - left, MARGIN - upper  # nothing left of or above the margin

    def mv(b: Box) -> Box:
        return Box(b.x + shift_x, b.y + shift_y, b.w, b.h)

    return FlowsheetLayout(
        units={u: mv(b) for u, b in boxes.items()},
        routes={n: [(x + shift_x, y + shift_y) for x, y in r] for n, r in routes.items()},
        labels={n: mv(b) for n, b in labels.items()}, recycle=back,
        width=right + shift_x + MARGIN, height=lowest + shift_y + MARGIN)


def crossings(boxes: dict, routes: dict, streams: dict) -> list[tuple[str, str]]:
    """Pairs (stream, unit) where a stream's route passes through another unit's box.

    (stream, unit) pairs where a stream's route passes through a unit box other than its
    own source and target (boxes shrunk by 2 px on each side).
    """
    out = []
    for n, route in routes.items():
        ends = set(streams[n])
        for u, b in boxes.items():
            if u not in ends and _route_hits(route, b):
                out.append((n, u))
    return out


def _route_hits(route, b: Box) -> bool:
    inner = Box(b.x, b.y, b.w - 4, b.h - 4)
    return any(_segment_hits(p, q, inner) for p, q in zip(route[:-1], route[1:]))


def _detour(boxes: dict, routes: dict, streams: dict, back: dict, dx: float = DX) -> None:
    """Reroute a stream whose route crosses another unit's box.

    Reroute a stream whose route crosses another unit's box through the free corridors
    beside the columns (between layer columns no unit stands): out of the source's side,
    along the corridor, into the target's side; a recycle keeps its lane below the row and
    moves only the legs down to it and up from it. Each detour takes its own track.
    """
    used: dict = {}

    def corridor(box, sign):
        base = box.x + sign * (0.5 * dx - 24)
        return base - sign * 10.0 * used.get(round(base), 0), round(base)

    for n, route in list(routes.items()):
        s, t = streams[n]
        others = [b for u, b in boxes.items() if u not in (s, t)]
        if not any(_route_hits(route, b) for b in others):
            continue
        a, b = boxes[s], boxes[t]
        cands = []
        if back[n]:
            lane = route[1][1]
            downs = [(route[:2], None)]
            ups = [(route[2:], None)]
            for sign in (1, -1):
                xc, key = corridor(a, sign)
                ya = a.y + 8.0 * sign
                downs.append(([(a.x + sign * a.w / 2, ya), (xc, ya), (xc, lane)], key))
                xt, key_t = corridor(b, sign)
                yb = b.y - 8.0 * sign
                ups.append(([(xt, lane), (xt, yb), (b.x + sign * b.w / 2, yb)], key_t))
            for down, k1 in downs:
                for up, k2 in ups:
                    cands.append((down + up, [k for k in (k1, k2) if k is not None]))
        else:
            for sign in (1, -1):
                xc, key = corridor(a, sign)
                ya = a.y + 8.0 * sign
                end_x = b.x - b.w / 2 if b.x > xc else b.x + b.w / 2
                cands.append(([(a.x + sign * a.w / 2, ya), (xc, ya), (xc, b.y), (end_x, b.y)], [key]))
        best = next((c for c in cands if not any(_route_hits(c[0], o) for o in others)), cands[-1])
        routes[n] = best[0]
        for k in best[1]:
            used[k] = used.get(k, 0) + 1


def _segment_hits(p, q, b: Box) -> bool:
    """Whether the segment p-q passes through the box (Liang-Barsky clipping)."""
    (x0, y0), (x1, y1) = p, q
    t0, t1 = 0.0, 1.0
    for d, lo, hi, o in ((x1 - x0, b.x - b.w / 2, b.x + b.w / 2, x0), (y1 - y0, b.y - b.h / 2, b.y + b.h / 2, y0)):
        if d == 0:
            if not lo < o < hi:
                return False
            continue
        a, c = (lo - o) / d, (hi - o) / d
        t0, t1 = max(t0, min(a, c)), min(t1, max(a, c))
        if t0 >= t1:
            return False
    return True


def _label_segment(route: list, recycle: bool) -> list:
    """The part of a route its label sits on: a recycle's lane (its lowest horizontal segment), else the whole route."""
    if not recycle:
        return route
    flat = [(p, q) for p, q in zip(route[:-1], route[1:]) if abs(p[1] - q[1]) < 1e-9 and p[0] != q[0]]
    if not flat:
        return route
    p, q = max(flat, key=lambda s: s[0][1])
    return [p, q]


def _area(c: tuple, boxes: list) -> float:
    """Overlap area of the box ``c`` = (x0, x1, y0, y1) with the boxes (same form)."""
    a = 0.0
    x0, x1, y0, y1 = c
    for bx0, bx1, by0, by1 in boxes:
        dx = min(x1, bx1) - max(x0, bx0)
        if dx > 0:
            dy = min(y1, by1) - max(y0, by0)
            if dy > 0:
                a += dx * dy
    return a


def _place_labels(boxes: dict, routes: dict, back: dict, sizes: dict, pad: float = 4.0) -> dict:
    """Place each label along its route where it overlaps nothing.

    Each label at the first candidate point along its route (the middle first, then
    outwards, then stepped off the route) whose box, grown by ``pad``, overlaps no unit box
    and no label placed before; among those, the one crossing the fewest other routes.
    When none is free, the least-overlapping candidate.
    """
    placed: dict = {}

    def edges(b):
        return (b.x - b.w / 2 - pad, b.x + b.w / 2 + pad, b.y - b.h / 2 - pad, b.y + b.h / 2 + pad)

    taken = [edges(b) for b in boxes.values()]
    segs = {n: list(zip(r[:-1], r[1:])) for n, r in routes.items()}
    ts = (0.5, 0.4, 0.6, 0.3, 0.7, 0.2, 0.8, 0.1, 0.9)
    offsets = (0.0,) + tuple(float(s * k) for k in range(1, 9) for s in (1, -1))
    for n, full in routes.items():
        w, h = sizes[n]
        others = [s for m, ss in segs.items() if m != n for s in ss]
        best, best_cost = None, (float("inf"), 0)
        # a recycle's lane first, then anywhere along its route
        for route in ([_label_segment(full, True), full] if back[n] else [full]):
            (x0, y0), (x1, y1) = route[0], route[-1]
            horizontal = abs(x1 - x0) >= abs(y1 - y0)
            for off in offsets:
                for t in ts:
                    px, py = _point_on(route, t)
                    if horizontal:
                        py += off * (h * 0.55 + 2)
                    else:
                        px += off * (w * 0.55 + 2)
                    area = _area((px - w / 2, px + w / 2, py - h / 2, py + h / 2), taken)
                    if area > 0 and best_cost[0] == 0:
                        continue
                    cand = Box(px, py, w, h)
                    hits = sum(_segment_hits(p, q, cand) for p, q in others) if area == 0 else 0
                    cost = (area, hits)
                    if cost < best_cost:
                        best, best_cost = cand, cost
                    if cost == (0, 0):
                        break
                if best_cost == (0, 0):
                    break
            if best_cost[0] == 0:
                break
        placed[n] = best
        taken.append(edges(best))
    return placed


def overlaps(lay: FlowsheetLayout) -> list[tuple[str, str]]:
    """Pairs of boxes (``unit:NAME`` or ``stream:NAME``) of the layout that overlap."""
    items = [(f"unit:{u}", b) for u, b in lay.units.items()] + [(f"stream:{n}", b) for n, b in lay.labels.items()]
    return [(a, c) for i, (a, b) in enumerate(items) for c, d in items[i + 1:] if b.overlap(d) > 0]
