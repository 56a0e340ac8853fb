#!/usr/bin/env python3
"""Dense 3D surfacing programs for the planner benchmark (issue 14), made by a real CAM kernel:
opencamlib (PyPI `opencamlib`, the kernel FreeCAD's 3D surface operation uses), pinned by
benches/planner_vs_linuxcnc.sh, which runs this in a venv under target/.

Two surfaces drawn here, tessellated into a triangle mesh (also written as ASCII STL next to
the programs, so the input is inspectable): a spherical dome and a wave. Three toolpaths,
the kinds of a 3D finishing pass:

  ocl_dome_zigzag.ngc      drop-cutter along zig-zag lines over the dome (ball end mill)
  ocl_wave_zigzag.ngc      drop-cutter along zig-zag lines over the wave (ball end mill)
  ocl_dome_waterline.ngc   waterline (constant-Z contours) around the dome

The drop-cutter points (sampled every 0.1 mm, adaptively refined) are reduced with
opencamlib's LineCLFilter at 0.01 mm, as FreeCAD does, and written the way a CAM post writes
them: one `G1 X Y Z` per point, three decimals, G64 P0.01, F3000 (50 mm/s, the benchmark's
velocity limit), rapids at a safe height between passes.

    python3 ocl_programs.py OUT_DIR
"""

import math
import os
import sys

import opencamlib as ocl

FEED = 3000.0  # mm/min
SAFE_Z = 15.0
TOL = 0.01  # G64 P and the LineCLFilter tolerance, mm
SAMPLING = 0.1  # drop-cutter sampling, mm
SIZE = 40.0  # side of the square blank, mm
MESH = 0.5  # mesh spacing, mm


def dome(x, y):
    """Spherical cap, radius 30 mm, 10 mm tall, centred on the blank."""
    r2 = (x - SIZE / 2) ** 2 + (y - SIZE / 2) ** 2
    return max(0.0, math.sqrt(max(0.0, 30.0**2 - r2)) - 20.0)


def wave(x, y):
    """Crossed sine waves, 2.5 mm amplitude."""
    return 3.0 + 2.5 * math.sin(x / 6.0) * math.cos(y / 8.0)


def mesh(f):
    """Triangles of a regular grid over the blank, as vertex triples."""
    n = int(round(SIZE / MESH))
    pts = [[(i * MESH, j * MESH, f(i * MESH, j * MESH)) for j in range(n + 1)] for i in range(n + 1)]
    tris = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = pts[i][j], pts[i + 1][j], pts[i + 1][j + 1], pts[i][j + 1]
            tris.append((a, b, c))
            tris.append((a, c, d))
    return tris


def write_stl(path, name, tris):
    with open(path, "w") as out:
        out.write("solid %s\n" % name)
        for t in tris:
            out.write(" facet normal 0 0 0\n  outer loop\n")
            for v in t:
                out.write("   vertex %.6f %.6f %.6f\n" % v)
            out.write("  endloop\n endfacet\n")
        out.write("endsolid %s\n" % name)


def surf(tris):
    s = ocl.STLSurf()
    for t in tris:
        s.addTriangle(ocl.Triangle(*(ocl.Point(*v) for v in t)))
    return s


class Post:
    """A minimal LinuxCNC post: absolute mm, G64 P, feed moves rounded to 3 decimals."""

    def __init__(self, title):
        self.lines = [
            "(%s)" % title,
            "(made with opencamlib %s by benches/programs/ocl_programs.py)" % ocl.version(),
            "G21 G90 G17 G94 G40 G49 G80",
            "G64 P%g" % TOL,
            "G0 Z%.3f" % SAFE_Z,
        ]
        self.last = None

    def rapid_to(self, p):
        self.lines.append("G0 Z%.3f" % SAFE_Z)
        self.lines.append("G0 X%.3f Y%.3f" % (p.x, p.y))
        self.lines.append("G0 Z%.3f" % (p.z + 2.0))
        self.lines.append("G1 Z%.3f F%g" % (p.z, FEED))
        self.last = ("%.3f" % p.x, "%.3f" % p.y, "%.3f" % p.z)

    def feed(self, p):
        cur = ("%.3f" % p.x, "%.3f" % p.y, "%.3f" % p.z)
        if cur != self.last:
            self.lines.append("G1 X%s Y%s Z%s" % cur)
            self.last = cur

    def write(self, path):
        self.lines += ["G0 Z%.3f" % SAFE_Z, "M2"]
        with open(path, "w") as out:
            out.write("\n".join(self.lines) + "\n")


def zigzag(stl, cutter, step, title, path):
    """Drop-cutter along lines in X, alternating direction, `step` apart in Y."""
    post = Post(title)
    n = int(round(SIZE / step))
    first = True
    for k in range(n + 1):
        y = k * step
        x0, x1 = (0.0, SIZE) if k % 2 == 0 else (SIZE, 0.0)
        p = ocl.Path()
        p.append(ocl.Line(ocl.Point(x0, y, 0), ocl.Point(x1, y, 0)))
        apdc = ocl.AdaptivePathDropCutter()
        apdc.setSTL(stl)
        apdc.setCutter(cutter)
        apdc.setSampling(SAMPLING)
        apdc.setMinSampling(SAMPLING / 10)
        apdc.setPath(p)
        apdc.run()
        filt = ocl.LineCLFilter()
        filt.setTolerance(TOL)
        for cl in apdc.getCLPoints():
            filt.addCLPoint(cl)
        filt.run()
        pts = filt.getCLPoints()
        if first:
            post.rapid_to(pts[0])
            first = False
        else:
            # Step over at cutting height, as a zig-zag finishing pass does.
            post.feed(pts[0])
        for cl in pts[1:]:
            post.feed(cl)
    post.write(path)


def waterline(stl, cutter, levels, title, path):
    """Constant-Z contours, top down; each loop closed, rapid between loops."""
    post = Post(title)
    for z in levels:
        wl = ocl.Waterline()
        wl.setSTL(stl)
        wl.setCutter(cutter)
        wl.setZ(z)
        wl.setSampling(SAMPLING)
        wl.run()
        for loop in wl.getLoops():
            if len(loop) < 3:
                continue
            post.rapid_to(loop[0])
            for p in loop[1:]:
                post.feed(p)
            post.feed(loop[0])
    post.write(path)


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    ball = ocl.BallCutter(3.0, 20.0)  # 3 mm ball end mill, 20 mm flute length
    dome_tris = mesh(dome)
    wave_tris = mesh(wave)
    write_stl(os.path.join(out, "ocl_dome.stl"), "dome", dome_tris)
    write_stl(os.path.join(out, "ocl_wave.stl"), "wave", wave_tris)
    dome_stl, wave_stl = surf(dome_tris), surf(wave_tris)
    zigzag(dome_stl, ball, 1.5, "opencamlib drop-cutter zig-zag over a dome, G64 P0.01",
           os.path.join(out, "ocl_dome_zigzag.ngc"))
    zigzag(wave_stl, ball, 1.5, "opencamlib drop-cutter zig-zag over a wave, G64 P0.01",
           os.path.join(out, "ocl_wave_zigzag.ngc"))
    # Levels where the dome and the cutter stay inside the blank (at z < 4 the cap meets its edge).
    waterline(dome_stl, ball, [9.0, 7.5, 6.0, 4.5],
              "opencamlib waterline around a dome, G64 P0.01",
              os.path.join(out, "ocl_dome_waterline.ngc"))


if __name__ == "__main__":
    main()
