"""The bolt map as an operator reads it, measured in the browser: each dot's screen centre and
radius, each shown label's screen box and its leader line, and which labels could be taken
for another bolt's (the screens' tests of the labels share this one rule)."""

from __future__ import annotations

from typing import Any

import numpy as np

from tests.web.pages import Page

# a label's own dot must be clearly the nearest: "B21" 14 px from its dot and 20 px from
# B25's (box edges) was read as B25's
LEAD, LEAD_CENTRE = 1.3, 1.2

GEOMETRY_JS = """
    const dots = {}, labels = {}, leaders = {};
    for (const g of document.querySelectorAll('#bolts g.bolt')) {
        const c = g.querySelector('circle').getBoundingClientRect();
        dots[g.dataset.bolt] = [(c.left + c.right) / 2, (c.top + c.bottom) / 2,
                                parseFloat(g.querySelector('circle').getAttribute('r'))];
        const l = g.querySelector('g.lbl');
        if (getComputedStyle(l).visibility === 'hidden') continue;
        const r = l.getBoundingClientRect();
        labels[g.dataset.bolt] = [r.left, r.top, r.right, r.bottom];
        const line = g.querySelector('line.leader');
        if (line) {
            const m = line.getScreenCTM(), a = ['x1', 'y1', 'x2', 'y2']
                .map(k => parseFloat(line.getAttribute(k)));
            const p = new DOMPoint(a[0], a[1]).matrixTransform(m),
                  q = new DOMPoint(a[2], a[3]).matrixTransform(m);
            leaders[g.dataset.bolt] = [p.x, p.y, q.x, q.y];
        }
    }
    const m = document.getElementById('map').getBoundingClientRect();
    return {dots, labels, leaders, map: [m.width, m.height]};"""


def map_geometry(page: Page) -> dict[str, Any]:
    """``dots`` (bolt -> x, y, r), ``labels`` (shown ones: bolt -> left, top, right,
    bottom), ``leaders`` (bolt -> x1, y1, x2, y2), ``map`` (width, height): screen px."""
    got: dict[str, Any] = page.js(GEOMETRY_JS)
    return got


def box_dist(box: list[float], x: float, y: float) -> float:
    """From a point to a box's nearest edge (0 inside)."""
    dx = max(box[0] - x, 0.0, x - box[2])
    dy = max(box[1] - y, 0.0, y - box[3])
    return float(np.hypot(dx, dy))


def seg_dist(seg: list[float], x: float, y: float) -> float:
    """From a point to a line segment (x1, y1, x2, y2)."""
    a, b = np.array(seg[:2]), np.array(seg[2:])
    d = b - a
    t = float(np.clip(np.dot([x, y] - a, d) / max(float(np.dot(d, d)), 1e-9), 0.0, 1.0))
    return float(np.hypot(*(a + t * d - [x, y])))


def confusable(geo: dict[str, Any]) -> list[str]:
    """Each shown label an operator could take for another bolt's: without a leader line,
    its own dot not clearly the nearest (every other dot at least :data:`LEAD` times as far
    from the box's nearest edge, plus 2 px, and :data:`LEAD_CENTRE` times from its centre);
    with one, a line that does not run from its own dot to its box or passes over another
    dot; and any label over a dot."""
    out = []
    for b, box in geo["labels"].items():
        x, y, r = geo["dots"][b]
        cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
        own, own_c = box_dist(box, x, y), float(np.hypot(cx - x, cy - y))
        line = geo["leaders"].get(b)
        if line is not None and (abs(np.hypot(line[0] - x, line[1] - y) - r) > 3
                                 or box_dist(box, line[2], line[3]) > 3):
            out.append(f"{b}: its leader does not join its dot and its label")
        for o, (ox, oy, orad) in geo["dots"].items():
            if o == b:
                continue
            if box_dist(box, ox, oy) < orad - 1:
                out.append(f"{b} label over {o}'s dot")
            if line is not None:
                if seg_dist(line, ox, oy) < orad + 1:
                    out.append(f"{b}: its leader passes over {o}")
            elif box_dist(box, ox, oy) < LEAD * own + 2 \
                    or np.hypot(cx - ox, cy - oy) < LEAD_CENTRE * own_c:
                out.append(f"{b} label {own:.0f}px (centre {own_c:.0f}) from its dot, "
                           f"{box_dist(box, ox, oy):.0f}px from {o}")
    return out
