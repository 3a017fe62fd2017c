"""Where the boxes of a flowsheet drawing go: units, stream routes and stream labels.

One layout serves the SVG of ``report.html`` and ``flowsheet.png``. Units are placed in
layers by their distance from the feeds (breadth-first), :data:`LAYERS_PER_ROW` layers to a
row, and a long circuit wraps onto further rows that run back (boustrophedon), so a wrapped
loop stays short. A stream to an earlier or the same layer (a recycle) is routed below its
row in a lane of its own, so recycle arcs never cross the units. Each stream's label box is
placed greedily at the first of a list of candidate points along its route whose box
overlaps no unit box and no label placed before it (the least-overlapping candidate when
none is free); :func:`overlaps` counts what is left, and the tests require none for the
shipped flowsheets and for 20-unit chains.

Coordinates are pixels of the drawing, y downwards (as in SVG).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

__all__ = ["Box", "FlowsheetLayout", "layout", "overlaps", "crossings", "LAYERS_PER_ROW"]

#: Layers per row of the drawing: longer circuits wrap onto further rows.
LAYERS_PER_ROW = 5
UNIT_W, UNIT_H = 136.0, 46.0
DX, DY = 340.0, 150.0  # spacing of layers and of units within a layer
LANE = 26.0  # spacing of recycle lanes below a row
LINE_H = 15.0  # label line height
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


def layout(units: dict, streams: dict, label_lines: int = 4) -> FlowsheetLayout:
    """Lay out a flowsheet.

    Parameters
    ----------
    units : dict
        Unit name -> unit type (``feed``, ``mill``, ``product``, ...), in file order.
    streams : dict
        Stream name -> (source unit, target unit), in file order.
    label_lines : int
        Lines of text in each stream label (sets the label box height).
    """
    level = _levels(units, streams)
    per_level: dict[int, list] = {}
    for u in units:
        per_level.setdefault(level[u], []).append(u)
    n_levels = max(level.values()) + 1
    n_rows = (n_levels - 1) // LAYERS_PER_ROW + 1
    back = {n: level[t] <= level[s] for n, (s, t) in streams.items()}
    row_of = {u: level[u] // LAYERS_PER_ROW for u in units}
    lanes_per_row = [0] * n_rows
    for n, (s, t) in streams.items():
        if back[n]:
            lanes_per_row[max(row_of[s], row_of[t])] += 1
    label_h = LINE_H * label_lines + 6
    depth = [max((len(v) for lv, v in per_level.items() if lv // LAYERS_PER_ROW == r), default=1)
             for r in range(n_rows)]
    top, row_top = MARGIN + label_h, []
    for r in range(n_rows):
        row_top.append(top)
        top += (depth[r] - 1) * DY + UNIT_H + 2 * LANE + LANE * lanes_per_row[r] + label_h + 60
    boxes = {}
    for lv, names in per_level.items():
        row, col = divmod(lv, LAYERS_PER_ROW)
        if row % 2:
            col = LAYERS_PER_ROW - 1 - col
        for k, u in enumerate(names):
            boxes[u] = Box(MARGIN + LABEL_W / 2 + UNIT_W / 2 + col * DX, row_top[row] + UNIT_H / 2 + k * DY,
                           UNIT_W, UNIT_H)
    routes, lane_used = {}, [0] * n_rows
    for n, (s, t) in streams.items():
        a, b = boxes[s], boxes[t]
        if not back[n]:
            routes[n] = [_clip(a, b.x, b.y), _clip(b, a.x, a.y)]
            continue
        r = max(row_of[s], row_of[t])
        bottom = max(bx.y + bx.h / 2 for u, bx in boxes.items() if row_of[u] == r)
        lane_used[r] += 1
        y = bottom + LANE * (lane_used[r] + 0.5)
        if s == t:
            routes[n] = [(a.x + a.w / 4, a.y + a.h / 2), (a.x + a.w / 4, y), (a.x - a.w / 4, y),
                         (a.x - a.w / 4, a.y + a.h / 2)]
        else:
            dx = 10.0 * (1 if b.x > a.x else -1)
            routes[n] = [(a.x + dx, a.y + a.h / 2), (a.x + dx, y), (b.x - dx, y), (b.x - dx, b.y + b.h / 2)]
    _detour(boxes, routes, streams, back)
    labels = _place_labels(boxes, routes, back, LABEL_W, label_h)
    right = max(max(b.x + b.w / 2 for b in boxes.values()), max(b.x + b.w / 2 for b in labels.values()),
                max(p[0] for r in routes.values() for p in r))
    lowest = max(max(b.y + b.h / 2 for b in labels.values()), max(p[1] for r in routes.values() for p in r),
                 max(b.y + b.h / 2 for b in boxes.values()))
    left = min(min(b.x - b.w / 2 for b in labels.values()), MARGIN)
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
    """(stream, unit) pairs where a stream's route passes through a unit box other than its
    own source and target (sampled every 4 px, boxes shrunk by 2 px)."""
    out = []
    for n, route in routes.items():
        ends = set(streams[n])
        for u, b in boxes.items():
            if u not in ends and _route_hits(route, b):
                out.append((n, u))
    return out


def _route_hits(route, b: Box) -> bool:
    for (x0, y0), (x1, y1) in zip(route[:-1], route[1:]):
        steps = max(1, int(((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5 / 4))
        for k in range(steps + 1):
            x, y = x0 + (x1 - x0) * k / steps, y0 + (y1 - y0) * k / steps
            if abs(x - b.x) < b.w / 2 - 2 and abs(y - b.y) < b.h / 2 - 2:
                return True
    return False


def _detour(boxes: dict, routes: dict, streams: dict, back: dict) -> None:
    """Reroute a stream whose route crosses another unit's box through the free corridors
    beside the columns (between layer columns no unit stands): out of the source's side,
    along the corridor, into the target's side; a recycle keeps its lane below the row and
    moves only the legs down to it and up from it. Each detour takes its own track."""
    used: dict = {}

    def corridor(box, sign):
        base = box.x + sign * (box.w / 2 + 0.5 * (DX - UNIT_W) - 24)
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


def _place_labels(boxes: dict, routes: dict, back: dict, w: float, h: float) -> dict:
    placed: dict = {}
    obstacles = list(boxes.values())
    ts = (0.5, 0.4, 0.6, 0.3, 0.7, 0.2, 0.8)
    for n, route in routes.items():
        if back[n]:  # on the lane: the horizontal middle segment
            route = route[1:3]
        (x0, y0), (x1, y1) = route[0], route[-1]
        horizontal = abs(x1 - x0) >= abs(y1 - y0)
        offsets = (0.0, 1.0, -1.0, 2.0, -2.0, 3.0, -3.0)
        best, best_cost = None, float("inf")
        for off in offsets:
            for t in ts:
                px, py = _point_on(route, t)
                if horizontal:
                    py += off * (h * 0.55)
                else:
                    px += off * (w * 0.55)
                cand = Box(px, py, w, h)
                cost = sum(cand.overlap(o, pad=4.0) for o in obstacles + list(placed.values()))
                if cost < best_cost:
                    best, best_cost = cand, cost
                if cost == 0:
                    break
            if best_cost == 0:
                break
        placed[n] = best
    return placed


def overlaps(lay: FlowsheetLayout) -> list[tuple[str, str]]:
    """Pairs of boxes (``unit:NAME`` or ``stream:NAME``) of the layout that overlap."""
    items = [(f"unit:{u}", b) for u, b in lay.units.items()] + [(f"stream:{n}", b) for n, b in lay.labels.items()]
    return [(a, c) for i, (a, b) in enumerate(items) for c, d in items[i + 1:] if b.overlap(d) > 0]
