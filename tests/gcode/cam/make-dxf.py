#!/usr/bin/env python3
"""Writes the DXF drawings (R12 ASCII, LINE/ARC/CIRCLE entities only) that
generate.sh turns into G-code with dxf2gcode. Drawn for this repository; millimetres."""
import math
import os
import sys


def dxf(entities):
    out = ["0", "SECTION", "2", "HEADER", "9", "$INSUNITS", "70", "4", "0", "ENDSEC",
           "0", "SECTION", "2", "ENTITIES"]
    for e in entities:
        out += e
    out += ["0", "ENDSEC", "0", "EOF"]
    return "\n".join(out) + "\n"


def line(x1, y1, x2, y2, layer="0"):
    return ["0", "LINE", "8", layer, "10", "%.4f" % x1, "20", "%.4f" % y1, "30", "0.0",
            "11", "%.4f" % x2, "21", "%.4f" % y2, "31", "0.0"]


def arc(cx, cy, r, a0, a1, layer="0"):
    return ["0", "ARC", "8", layer, "10", "%.4f" % cx, "20", "%.4f" % cy, "30", "0.0",
            "40", "%.4f" % r, "50", "%.4f" % a0, "51", "%.4f" % a1]


def circle(cx, cy, r, layer="0"):
    return ["0", "CIRCLE", "8", layer, "10", "%.4f" % cx, "20", "%.4f" % cy, "30", "0.0",
            "40", "%.4f" % r]


def rounded_rect(x0, y0, w, h, r, layer="0"):
    x1, y1 = x0 + w, y0 + h
    return [line(x0 + r, y0, x1 - r, y0, layer), arc(x1 - r, y0 + r, r, 270, 360, layer),
            line(x1, y0 + r, x1, y1 - r, layer), arc(x1 - r, y1 - r, r, 0, 90, layer),
            line(x1 - r, y1, x0 + r, y1, layer), arc(x0 + r, y1 - r, r, 90, 180, layer),
            line(x0, y1 - r, x0, y0 + r, layer), arc(x0 + r, y0 + r, r, 180, 270, layer)]


def plate():
    """A mounting plate: rounded outline, four holes, a slot."""
    e = rounded_rect(0, 0, 120, 80, 8)
    for x, y in [(12, 12), (108, 12), (12, 68), (108, 68)]:
        e.append(circle(x, y, 3.3))
    # slot 40 x 10 with round ends
    e += [line(45, 35, 75, 35), arc(75, 40, 5, 270, 90), line(75, 45, 45, 45),
          arc(45, 40, 5, 90, 270)]
    return e


def gear_outline(n=12, r_root=30.0, r_tip=36.0):
    """A star-like cam profile of straight flanks and tip arcs around a centre bore."""
    e = []
    pts = []
    for i in range(n):
        a = 2 * math.pi * i / n
        b = a + math.pi / n
        pts.append((r_root * math.cos(a), r_root * math.sin(a)))
        pts.append((r_tip * math.cos(b - 0.08), r_tip * math.sin(b - 0.08), b))
    for i in range(n):
        x0, y0 = pts[2 * i]
        tx, ty, b = pts[2 * i + 1]
        ex, ey = r_tip * math.cos(b + 0.08), r_tip * math.sin(b + 0.08)
        nx, ny = pts[(2 * i + 2) % (2 * n)][:2]
        e.append(line(x0, y0, tx, ty))
        e.append(arc(0, 0, r_tip, math.degrees(b - 0.08), math.degrees(b + 0.08)))
        e.append(line(ex, ey, nx, ny))
    e.append(circle(0, 0, 8))
    return e


def bracket():
    """An L bracket with an inside fillet and two holes."""
    e = [line(0, 0, 60, 0), line(60, 0, 60, 12), line(60, 12, 18, 12),
         arc(18, 18, 6, 180, 270), line(12, 18, 12, 50), line(12, 50, 0, 50),
         line(0, 50, 0, 0), circle(40, 6, 2.5), circle(6, 35, 2.5)]
    return e


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__))
    for name, ents in [("plate", plate()), ("cam", gear_outline()), ("bracket", bracket())]:
        with open(os.path.join(d, name + ".dxf"), "w") as f:
            f.write(dxf(ents))


if __name__ == "__main__":
    main()
