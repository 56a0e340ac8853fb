#!/usr/bin/env python3
"""Differential check of hytask's G-code interpreter against LinuxCNC's `rs274 -g`.

Two uses (standard library only; needs `rs274` from linuxcnc-uspace on PATH):

  rs274diff.py compare [--hytask BIN] FILE.ngc...
      runs each program through both, from the corpus directory with the corpus tool
      table, and prints `same`, `differs` (first differing call) or an acceptance mismatch.

  rs274diff.py random [--hytask BIN] [--seed N] [--count N] [--keep DIR] [--kind KIND]
      generates random programs (KIND mill, the default: see `gen_program`; KIND lathe:
      G70/G71/G71.2 on rounded profiles, see `gen_lathe_program`) and compares them the
      same way; the programs that differ are written to DIR (default: a temporary
      directory) so that they can be reduced and kept as corpus cases.

Not run by CI (a few thousand programs take minutes); the corpus programs it found are
checked by `tests/gcode_differential.rs`. Traces are compared after dropping the
sequence-number and N-word columns, as the Rust test does.
"""
import argparse
import math
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
CORPUS = os.path.join(HERE, "corpus")
PREFIX = re.compile(r"^\s*\d+ N\S*\s+")


# rs274's G7x offset prints this debugging line to standard output (into the trace) when it
# drops an element that runs against the feed; hytask drops the element without printing
# (DIFFERENCES.md). A trace that differs only by these lines is counted apart.
OOPS = "Oops ("
ONLY_OOPS = "only rs274's debugging line(s) 'Oops (...)' differ"


def strip(text):
    return [PREFIX.sub("", line) for line in text.splitlines()]


def run(cmd, cwd):
    try:
        p = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=60,
                           errors="replace")
    except subprocess.TimeoutExpired:
        return None, "", "timeout"
    return p.returncode, p.stdout, p.stderr


def compare(path, hytask):
    """Returns None when both agree, else a one-line description."""
    d = os.path.dirname(os.path.abspath(path))
    tbl = os.path.join(CORPUS, "tool.tbl")
    rc_r, out_r, err_r = run(["rs274", "-t", tbl, "-g", os.path.abspath(path)], d)
    if rc_r is None:
        return None  # rs274 hangs on some programs; nothing to compare
    if rc_r not in (0, 1) and not out_r:
        return None  # rs274 crashed (it does on a few random programs)
    rc_h, out_h, err_h = run([hytask, "gcode", "canon", "--tool-table", tbl,
                              os.path.abspath(path)], d)
    if rc_h is None:
        return "hytask timed out"
    if rc_r != 0 and rc_h == 0:
        return "rs274 rejects, hytask accepts: " + err_r.strip().replace("\n", " | ")[-200:]
    if rc_r == 0 and rc_h != 0:
        return "rs274 accepts, hytask rejects: " + err_h.strip().replace("\n", " | ")[-200:]
    if rc_r != 0:
        return None
    a, b = strip(out_h), strip(out_r)
    if a == b:
        return None
    if a == [line for line in b if not line.startswith(OOPS)]:
        return ONLY_OOPS
    i = next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b)))
    return "call %d: hytask %r, rs274 %r" % (
        i + 1, a[i] if i < len(a) else "<end>", b[i] if i < len(b) else "<end>")


# ---------------------------------------------------------------- random programs

def num(r, lo=-5.0, hi=5.0, digits=3):
    return ("%." + str(digits) + "f") % r.uniform(lo, hi)


def axes(r, names="XYZ", lo=-5.0, hi=5.0, at_least=1):
    picked = [a for a in names if r.random() < 0.6]
    while len(picked) < at_least:
        picked = [r.choice(names)]
    return " ".join(a + num(r, lo, hi) for a in picked)


def gen_block(r, st):
    """One random line; `st` holds what the generator needs to stay mostly legal."""
    k = r.randrange(34)
    if k < 4:
        return "G%d %s" % (r.choice([0, 1, 1]), axes(r))
    if k < 7:  # arcs, R or centre form, optional turns
        g = r.choice(["G2", "G3"])
        if r.random() < 0.4:
            return "%s X%s Y%s R%s" % (g, num(r), num(r), num(r, 3, 9))
        p = " P%d" % r.randint(1, 3) if r.random() < 0.3 else ""
        return "%s X%s Y%s I%s J%s%s" % (g, num(r, -1, 1), num(r, -1, 1), num(r, -2, 2),
                                           num(r, -2, 2), p)
    if k < 9:  # canned cycles with repeats and incremental mode
        cyc = r.choice(["G81", "G82 P0.5", "G83 Q0.7", "G73 Q0.4", "G85", "G86 P0.2",
                        "G89 P0.3", "G84"])
        l = " L%d" % r.randint(1, 3) if r.random() < 0.4 else ""
        inc = r.random() < 0.3
        pre = "G91 " if inc else "G90 "
        z = num(r, -3, -0.5) if not inc else num(r, -4, -1)
        rr = num(r, 0.5, 2) if not inc else num(r, 0.2, 1)
        tail = " G80 G90" if r.random() < 0.5 else ""
        spin = "M3 S500 " if cyc == "G84" else ""
        return "%s%s%s %s X%s Y%s Z%s R%s%s\nG80 G90%s" % (
            spin, pre, r.choice(["G98", "G99"]), cyc, num(r), num(r), z, rr, l, tail)
    if k == 9:
        return "G10 L2 P%d %s" % (r.randint(0, 9), axes(r))
    if k == 10:
        return "G10 L20 P%d %s" % (r.randint(0, 9), axes(r))
    if k == 11:
        return "G10 L1 P%d Z%s R%s" % (r.choice([1, 2, 3, 7]), num(r, -1, 2), num(r, 0, 0.3))
    if k == 12:
        return "G43 H%d" % r.choice([1, 2, 3, 7]) if r.random() < 0.7 else "G49"
    if k == 13:
        return "G43.1 Z%s" % num(r, -1, 1)
    if k == 14:
        return "G92 %s" % axes(r)
    if k == 15:
        return r.choice(["G92.1", "G92.2", "G92.3"])
    if k == 16:
        return r.choice(["G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"])
    if k == 17:
        return r.choice(["G20", "G21"])
    if k == 18:
        return r.choice(["G17", "G18", "G19"])  # arcs/cycles after it may be refused alike
    if k == 19:
        return r.choice(["G90", "G91", "G90", "G91.1", "G90.1"])
    if k == 20:
        return "G28 %s" % axes(r) if r.random() < 0.5 else r.choice(["G28", "G30", "G28.1",
                                                                       "G30.1"])
    if k == 21:
        return "G30 %s" % axes(r)
    if k == 22:
        return "G53 G0 %s" % axes(r)
    if k == 23:
        st["m70"] += 1
        return r.choice(["M70", "M73"]) if r.random() < 0.8 else "M71"
    if k == 24:
        return "M72" if st["m70"] > 0 else "M70"
    if k == 25:
        return "(DEBUG, #<_x> #<_y> #<_z> #5420 #5422 #5211 #5221 #5403 #<_coord_system>)"
    if k == 26:
        return "(DEBUG, #<_metric> #<_absolute> #<_incr> #<_plane> #<_feed> #<_rpm>" \
               " #<_current_tool> #<_selected_tool> #<_motion_mode> #<_tool_offset>)"
    if k == 27:
        return "T%d M6" % r.choice([1, 2, 3, 7]) if r.random() < 0.6 else \
            "M61 Q%d" % r.choice([0, 1, 2, 3, 7])
    if k == 28:
        return "F%s" % num(r, 10, 200, 1)
    if k == 29:
        return "G52 %s" % axes(r) if r.random() < 0.7 else "G52 X0 Y0 Z0"
    if k == 30:
        return "G10 L%s P%d %s" % (r.choice(["10", "11"]), r.choice([1, 2, 3, 7]),
                                   axes(r, "XZ"))
    if k == 31:
        return "G10 L2 P%d R%s" % (r.randint(1, 3), num(r, -45, 45, 1))
    if k == 32:
        return "G%s %s" % (r.choice(["5.1", "5"]),
                           "X%s Y%s I%s J%s" % (num(r), num(r), num(r, -2, 2), num(r, -2, 2))
                           + (" P%s Q%s" % (num(r, -2, 2), num(r, -2, 2)) if r.random() < 0.5
                              else ""))
    return "G%d %s" % (r.choice([0, 1]), axes(r))


def gen_program(seed):
    r = random.Random(seed)
    st = {"m70": 0}
    # T1 M6 first: before any M6, rs274's standalone tool table treats its first entry as
    # the tool in the spindle (see DIFFERENCES.md); hytask's spindle is empty.
    lines = ["G17 G20 G40 G49 G80 G90 G94 F40", "T1 M6", "G0 X0 Y0 Z1"]
    for _ in range(r.randint(5, 30)):
        b = gen_block(r, st)
        # G5 needs G17; keep the spline legal mostly, but let the odd plane through.
        if b.startswith("G5") and r.random() < 0.9:
            b = "G17 " + b
        lines.append(b)
    lines.append("M2")
    return "\n".join(lines) + "\n"


def gen_lathe_program(seed):
    """A G70, G71 or G71.2 cycle on a random outside profile (X rising, Z falling) of lines
    and arcs whose numbers are rounded to 4 decimals, so that joins meant to be tangent
    miss slightly, as in hand-written profiles; allowances from negative to 1, sometimes
    several G70 passes. rs274 refuses about half of them (profiles that turn back); those
    must be refused by hytask too."""
    r = random.Random(seed)
    x, z = round(r.uniform(0.5, 2), 3), 1.0
    lines = ["G1 X%s Z%s" % (x, z)]
    for _ in range(r.randint(3, 7)):
        k = r.random()
        if k < 0.5:
            nx = round(x + r.choice([0, 0, r.uniform(0, 1.5)]), 4)
            nz = round(z - r.uniform(0.3, 3), 4)
            lines.append("G1 X%s Z%s" % (nx, nz))
            x, z = nx, nz
        elif k < 0.7:
            x = round(x + r.uniform(0.2, 1.5), 4)
            lines.append("G1 X%s" % x)
        else:
            rad = r.uniform(0.5, 3)
            a0 = math.radians(r.uniform(0, 60))
            a1 = math.radians(r.uniform(math.degrees(a0) + 10, 90))
            if r.random() < 0.5:  # convex
                cx, cz = x - rad * math.sin(a0), z - rad * math.cos(a0)
                ex, ez, g = cx + rad * math.sin(a1), cz + rad * math.cos(a1), 3
            else:  # a groove
                cx, cz = x + rad * math.cos(a0), z - rad * math.sin(a0)
                ex, ez, g = cx - rad * math.cos(a1), cz - rad * math.sin(a1), 2
            ex, ez = round(ex, 4), round(ez, 4)
            if ez < z - 0.01:
                lines.append("G%d X%s Z%s I%s K%s"
                             % (g, ex, ez, round(cx - x, 4), round(cz - z, 4)))
                x, z = ex, ez
    sx = round(x + 2, 2)
    lines.append("G1 X%s" % round(x + 1, 3))
    cyc = r.choice(["G70", "G71", "G71.2", "G70"])
    if cyc == "G70":
        d = round(r.uniform(-0.3, 1.0), 2)
        e = round(r.uniform(0, d), 2) if d > 0 else 0
        words = "D%s E%s P%d" % (d, e, r.randint(1, 3))
    else:
        words = "D%s I%s R0.3" % (round(r.uniform(-0.2, 0.6), 2), round(r.uniform(0.3, 1.2), 2))
    return ("G18 G21 G90 F100\no1 sub\n%s\no1 endsub\nG0 X%s Z3\n%s Q1 X%s Z2 %s\n"
            "G0 X%s\nM2\n" % ("\n".join(lines), sx, cyc, sx, words, sx + 2))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["compare", "random"])
    ap.add_argument("files", nargs="*")
    ap.add_argument("--hytask", default=os.environ.get("HYTASK_BIN", "hytask"))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--count", type=int, default=200)
    ap.add_argument("--keep")
    ap.add_argument("--kind", choices=["mill", "lathe"], default="mill",
                    help="mill: gen_program; lathe: gen_lathe_program (G70/G71 cycles)")
    a = ap.parse_intermixed_args()
    if a.mode == "compare":
        bad = 0
        for f in a.files:
            d = compare(f, a.hytask)
            print("%s: %s" % (f, d or "same"))
            bad += d is not None
        sys.exit(1 if bad else 0)
    keep = a.keep or tempfile.mkdtemp(prefix="rs274diff-")
    os.makedirs(keep, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix="rs274diff-run-")
    bad = oops = 0
    try:
        for s in range(a.seed, a.seed + a.count):
            p = os.path.join(tmp, "random_%d.ngc" % s)
            with open(p, "w") as f:
                f.write(gen_lathe_program(s) if a.kind == "lathe" else gen_program(s))
            d = compare(p, a.hytask)
            if d:
                bad += 1
                oops += d == ONLY_OOPS
                shutil.copy(p, keep)
                print("random_%d: %s" % (s, d), flush=True)
    finally:
        shutil.rmtree(tmp)
    print("%d of %d programs differ, %d of them only by rs274's 'Oops' line (kept in %s)"
          % (bad, a.count, oops, keep))
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
