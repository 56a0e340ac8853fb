#!/usr/bin/env python3
"""Runs LinuxCNC's own G-code programs (or any directory of .ngc files) through LinuxCNC's
`rs274 -g` and `hytask gcode canon` and tabulates how they agree.

    ncfiles-diff.py [--hytask BIN] [--list] [--only CLASS] [DIR...]

Without DIR it takes every .ngc file of the installed Debian package `linuxcnc-uspace`
(`dpkg -L linuxcnc-uspace`: /usr/share/linuxcnc/ncfiles with ngcgui_lib, probe macros and
plasmac, the sample configurations' macros and remap subroutines, lathe programs). Those
files are GPL: they are read where installed, never copied into this repository.

Per program, both interpreters get the same setup, the one LinuxCNC's sample
configurations give it:
- tool table: the nearest `*.tbl` in the program's directory or a parent directory below
  the package's roots (a sample configuration's own table), else the corpus `tool.tbl`;
- subroutine path: the `SUBROUTINE_PATH` of the nearest `*.ini` (same search; relative
  entries resolved from the ini's directory), plus the program's own directory and the
  stock ngcgui/remap libraries. rs274 reads it from a generated one-section ini
  (`[RS274NGC] SUBROUTINE_PATH`; the real ini would also load Python remaps and HAL-side
  settings the standalone interpreter cannot run), hytask from `--subroutine-path`;
- machine units: inches for both (rs274 standalone; `--machine-units inch`).
A program below a DIR argument is a test of its own (LinuxCNC's interpreter suite,
tests/interp: one directory per test, whose test.sh runs `rs274 [-t test.tbl] [-i
test.ini] -g prog.ngc`): it gets its own directory's setup instead, the nearest `*.tbl`
and `*.ini` in its directory or a parent below the DIR (else the corpus `tool.tbl`), and
rs274 reads that ini itself (`-i`), as the test does, and so does hytask (`--ini`: its
numbers as `#<_ini[…]>` values, its SUBROUTINE_PATH), with the test's `subs/` directory on
the path; the ini's machine settings (ORIENT_OFFSET, FEATURES, axis types) act in rs274
only.

Traces are compared with the differential suite's normalisation (tests/gcode_differential.rs):
  motion  only the motion calls (STRAIGHT_TRAVERSE, STRAIGHT_FEED, ARC_FEED, NURBS_FEED,
          STRAIGHT_PROBE, RIGID_TAP), prefix columns (sequence number, N word) dropped;
  calls   every line, prefix columns dropped (`strip` of the Rust test);
  bytes   the whole text, only the N-word column replaced by `N.....` (`normalise_bytes`).

Classes (one per program):
  same          both accept, same motion: the motion calls agree to 0.0001 (one unit of the
                last printed digit; the sign of a zero ignored: rs274 computes some angles
                in long double); "=exact" counts those whose motion text is identical,
                "=calls" and "=bytes" those whose whole trace matches strictly
  differ        both accept, different motion
  hytask-err    rs274 accepts, hytask errors
  rs274-err     hytask accepts, rs274 errors
  both-err      both error; "line match" when hytask's error line is one whose text is
                the block rs274 names (rs274 prints the failing block, not its number)
  subroutine    a file holding only `o<name> sub ... endsub` definitions (and at most a
                trailing M2/M30/%): a called program, not run alone; it is exercised by the
                programs that call it (rs274 run alone on one only reads the definition).
  rs274-hang    rs274 did not finish within --timeout (not counted in the figures).

The figure of merit is same / (same + differ + hytask-err): of the programs rs274 accepts,
the share on which hytask produces the same motion.
"""
import argparse
import collections
import os
import re
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
CORPUS_TBL = os.path.join(HERE, "corpus", "tool.tbl")
PACKAGE = "linuxcnc-uspace"
ROOTS = ["/usr/share/linuxcnc/ncfiles", "/usr/share/doc/linuxcnc/examples/sample-configs",
         "/usr/share/axis"]
SIM_AXIS = ROOTS[1] + "/sim/axis"
STOCK_SUBS = ["/usr/share/linuxcnc/ncfiles/ngcgui_lib",
              "/usr/share/linuxcnc/ncfiles/ngcgui_lib/utilitysubs",
              "/usr/share/linuxcnc/ncfiles/remap_lib/common_nc_subs"]
MOTION = ("STRAIGHT_TRAVERSE(", "STRAIGHT_FEED(", "ARC_FEED(", "NURBS_FEED(",
          "STRAIGHT_PROBE(", "RIGID_TAP(")
PREFIX = re.compile(r"^\s*\d+ N\S*\s+")
NCOL = re.compile(r"^(\s*\d+ N).{5}")
CLASSES = ["same", "differ", "hytask-err", "rs274-err", "both-err", "subroutine",
           "rs274-hang"]


def package_files():
    out = subprocess.run(["dpkg", "-L", PACKAGE], capture_output=True, text=True,
                         check=True).stdout
    return sorted(p for p in out.splitlines() if p.endswith(".ngc") and os.path.isfile(p))


def dir_files(d):
    found = []
    for root, _, names in os.walk(d):
        found += [os.path.join(root, n) for n in names if n.lower().endswith(".ngc")]
    return sorted(found)


def code_of(line):
    """The line without comments (parenthesised and `;`), stripped and lower-cased."""
    line = re.sub(r"\([^)]*\)", "", line).split(";")[0]
    return line.strip().lower()


def is_subroutine_file(path):
    """True when every executable line lies between `o<…> sub` and `o<…> endsub`."""
    depth, subs = 0, 0
    with open(path, errors="replace") as f:
        for raw in f:
            c = re.sub(r"^n\d+\s*", "", code_of(raw)).lstrip("/").strip()
            if not c or c == "%":
                continue
            if re.match(r"^o\S*\s*sub\b", c):
                depth += 1
                subs += 1
                continue
            if re.match(r"^o\S*\s*endsub\b", c):
                depth = max(0, depth - 1)
                continue
            if depth == 0 and not re.fullmatch(r"m0*(2|30)", c.replace(" ", "")):
                return False
    return subs > 0


def nearest(path, pattern, stop):
    """The first file matching `pattern` in path's directory or a parent below `stop`."""
    d = os.path.dirname(path)
    while True:
        try:
            hits = sorted(n for n in os.listdir(d) if re.fullmatch(pattern, n))
        except OSError:
            hits = []
        if hits:
            return os.path.join(d, hits[0])
        if d == stop or os.path.dirname(d) == d or not d.startswith(stop):
            return None
        d = os.path.dirname(d)


# The DIR arguments: a program below one of them takes its setup from its own test
# directory (see `setup_for`).
DIR_ROOTS = []


def root_of(path):
    """The package root or DIR argument a program lies below (else its own directory)."""
    roots = ROOTS + DIR_ROOTS
    hit = [r for r in roots if path.startswith(r.rstrip("/") + "/")]
    return max(hit, key=len).rstrip("/") if hit else os.path.dirname(path)


def in_dir_roots(path):
    return any(path.startswith(r.rstrip("/") + "/") for r in DIR_ROOTS)


def ini_values(ini):
    """SUBROUTINE_PATH ([RS274NGC]) and TOOL_TABLE ([EMCIO]) of an ini file, if set."""
    section, found = None, {}
    with open(ini, errors="replace") as f:
        for line in f:
            s = line.split("#")[0].strip()
            if s.startswith("["):
                section = s.strip("[]").strip()
            m = re.match(r"(SUBROUTINE_PATH|TOOL_TABLE)\s*=\s*(\S.*)", s)
            if m and section in ("RS274NGC", "EMCIO") and m.group(1) not in found:
                found[m.group(1)] = m.group(2).strip()
    return found


def resolve(base, p):
    return os.path.normpath(os.path.join(base, os.path.expanduser(p)))


def ini_for(path):
    """The sample configuration that runs a program: the nearest ini above it, else (the
    stock ncfiles) the sim/axis configuration LinuxCNC opens them with (lathe.ini for the
    lathe programs)."""
    root = root_of(path)
    ini = nearest(path, r".*\.ini", root)
    if ini is None and path.startswith(ROOTS[0] + "/"):
        lathe = "lathe" in os.path.relpath(path, ROOTS[0])
        ini = os.path.join(SIM_AXIS, "lathe.ini" if lathe else "axis.ini")
        ini = ini if os.path.isfile(ini) else None
    return ini


def setup_for(path):
    """(tool table, subroutine directories, ini, own) for one program.

    A program below a DIR argument (LinuxCNC's interpreter tests: one directory per test,
    run by its test.sh as `rs274 [-t test.tbl] [-i test.ini] -g prog.ngc`) gets its own
    test's setup: the nearest `*.tbl` and `*.ini` in its directory or a parent below the
    DIR, and `own` is true so that rs274 reads that ini itself, as the test does. The
    called files such a test keeps in `subs/` (its ini's SUBROUTINE_PATH) are searched too,
    also when the ini is not at hand."""
    ini = ini_for(path)
    vals = ini_values(ini) if ini else {}
    base = os.path.dirname(ini) if ini else ""
    tbl = None
    own = in_dir_roots(path)
    if own:
        tbl = nearest(path, r".*\.tbl", root_of(path))
    if "TOOL_TABLE" in vals:
        # a sample configuration's table may sit in a parent directory (sim/sim.tbl)
        name = vals["TOOL_TABLE"]
        d = base
        while d.startswith(ROOTS[1]) and tbl is None:
            c = resolve(d, name)
            tbl = c if os.path.isfile(c) else None
            d = os.path.dirname(d)
    subs = [os.path.dirname(path)]
    subs += [resolve(base, p) for p in vals.get("SUBROUTINE_PATH", "").split(":") if p]
    if own:
        subs.append(os.path.join(os.path.dirname(path), "subs"))
    subs += STOCK_SUBS
    seen = []
    for s in subs:
        if s not in seen and os.path.isdir(s):
            seen.append(s)
    return tbl or CORPUS_TBL, seen, ini, own and ini is not None


def run(cmd, cwd, timeout):
    try:
        p = subprocess.run(cmd, cwd=cwd, capture_output=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, "", ""
    dec = lambda b: b.decode("utf-8", errors="replace")  # noqa: E731
    return p.returncode, dec(p.stdout), dec(p.stderr)


def strip_calls(text):
    return [PREFIX.sub("", l) for l in text.splitlines()]


def motion(calls):
    return [c for c in calls if c.startswith(MOTION)]


NUM = re.compile(r"-?\d+\.\d+")


def same_motion(a, b):
    """Motion calls equal up to one unit of the last printed digit (0.0001) and the sign of
    a zero: rs274 computes some angles in x87 long double, hytask in double, which moves
    the last printed digit of a few results (tests/gcode/DIFFERENCES.md); that is the same
    motion. The strict comparisons are the calls and bytes columns."""
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if NUM.sub("#", x) != NUM.sub("#", y):
            return False
        for u, v in zip(NUM.findall(x), NUM.findall(y)):
            if abs(float(u) - float(v)) > 1.5e-4:
                return False
    return True


def norm_bytes(text):
    return [NCOL.sub(r"\1.....", l) for l in text.splitlines()]


def error_line_match(path, err_r, err_h):
    """hytask names file:line:col; rs274 prints the failing block's text as its last line."""
    m = re.search(r":(\d+):\d+: ", err_h)
    lines = [l for l in err_r.splitlines() if l.strip() and l.strip() != "executing"]
    if not m or len(lines) < 2:
        return False
    block = lines[-1].strip().lower().replace(" ", "")
    fname = re.search(r"hytask: (.*?):\d+:\d+: ", err_h)
    target = path
    if fname and os.path.basename(fname.group(1)) != os.path.basename(path):
        return None  # the error is in a called file; not compared
    try:
        with open(target, errors="replace") as f:
            text = f.read().splitlines()
    except OSError:
        return False
    n = int(m.group(1))
    return 0 < n <= len(text) and text[n - 1].strip().lower().replace(" ", "") == block


def classify(path, hytask, timeout, tmp):
    if is_subroutine_file(path):
        return {"class": "subroutine"}
    tbl, subs, ini, own = setup_for(path)
    cwd = os.path.dirname(path)
    base = ["rs274", "-t", tbl, "-g", path]
    with_ini = own
    rc_r, out_r, err_r = run(base[:1] + (["-i", ini] if own else []) + base[1:], cwd, timeout)
    if rc_r not in (0, None) and not own:
        # Only now the subroutine path: with any ini, rs274 prints one ON_RESET() fewer at
        # exit (an artefact of its standalone driver), dropped from hytask's trace below.
        ini = os.path.join(tmp, "sub.ini")
        with open(ini, "w") as f:
            f.write("[RS274NGC]\nSUBROUTINE_PATH = %s\n" % ":".join(subs))
        rc_i, out_i, err_i = run(base[:1] + ["-i", ini] + base[1:], cwd, timeout)
        if rc_i == 0:
            rc_r, out_r, err_r, with_ini = rc_i, out_i, err_i, True
    if rc_r is None:
        return {"class": "rs274-hang"}
    # --python: rs274 runs `;py,` comments (its embedded Python); hytask only on request.
    cmd = [hytask, "gcode", "canon", "--python", "--machine-units", "inch", "--tool-table", tbl]
    if own:
        cmd += ["--ini", ini]
    for s in subs:
        cmd += ["--subroutine-path", s]
    rc_h, out_h, err_h = run(cmd + [path], cwd, timeout)
    if with_ini and out_h.endswith("ON_RESET()\n"):
        out_h = out_h[:out_h.rstrip("\n").rfind("\n") + 1]
    ok_r, ok_h = rc_r == 0, rc_h == 0
    err_r_last = " | ".join(l for l in err_r.strip().splitlines() if l != "executing")[-160:]
    res = {"rs274": err_r_last, "hytask": err_h.strip()[-200:] if rc_h is not None
           else "timeout"}
    if ok_r and ok_h:
        cr, ch = strip_calls(out_r), strip_calls(out_h)
        res["calls"] = cr == ch
        res["bytes"] = norm_bytes(out_r) == norm_bytes(out_h)
        mr, mh = motion(cr), motion(ch)
        res["exact"] = mr == mh
        res["class"] = "same" if same_motion(mr, mh) else "differ"
        if res["class"] == "differ":
            i = next((i for i, (a, b) in enumerate(zip(mh, mr)) if a != b), min(len(mh),
                                                                                   len(mr)))
            res["first"] = "motion %d of %d/%d: hytask %s | rs274 %s" % (
                i + 1, len(mh), len(mr), mh[i] if i < len(mh) else "<end>",
                mr[i] if i < len(mr) else "<end>")
        if res["class"] == "same" and not res["calls"]:
            i = next((i for i, (a, b) in enumerate(zip(ch, cr)) if a != b), min(len(ch),
                                                                                   len(cr)))
            res["first"] = "call %d: hytask %s | rs274 %s" % (
                i + 1, ch[i] if i < len(ch) else "<end>", cr[i] if i < len(cr) else "<end>")
    elif ok_r:
        res["class"] = "hytask-err"
    elif ok_h:
        res["class"] = "rs274-err"
    else:
        res["class"] = "both-err"
        res["line_match"] = error_line_match(path, err_r, err_h)
    return res


def group_of(path, dirs):
    for d in dirs:
        if path.startswith(d.rstrip("/") + "/"):
            rel = os.path.relpath(os.path.dirname(path), d)
            return os.path.join(os.path.basename(d.rstrip("/")), rel) if rel != "." \
                else os.path.basename(d.rstrip("/"))
    for r in ROOTS:
        if path.startswith(r + "/"):
            parts = os.path.relpath(path, r).split("/")[:-1]
            key = parts[:3] if r.endswith("sample-configs") else parts[:1]
            return "/".join([os.path.basename(r)] + key)
    return os.path.dirname(path)


def table(rows, title):
    """rows: list of (group, result). Prints one line per group and a total."""
    by = collections.OrderedDict()
    for g, r in rows:
        by.setdefault(g, []).append(r)
    hdr = ["same", "=exact", "=calls", "=bytes", "differ", "hy-err", "rs-err", "both", "=line",
           "sub", "hang", "motion%"]
    print("\n" + title)
    print("%-58s %s" % ("directory", " ".join("%7s" % h for h in hdr)))

    def line(name, rs):
        c = collections.Counter(r["class"] for r in rs)
        exact = sum(1 for r in rs if r["class"] == "same" and r.get("exact"))
        same_calls = sum(1 for r in rs if r["class"] == "same" and r.get("calls"))
        same_bytes = sum(1 for r in rs if r["class"] == "same" and r.get("bytes"))
        lm = sum(1 for r in rs if r["class"] == "both-err" and r.get("line_match"))
        acc = c["same"] + c["differ"] + c["hytask-err"]
        pct = "%.1f" % (100.0 * c["same"] / acc) if acc else "-"
        vals = [c["same"], exact, same_calls, same_bytes, c["differ"], c["hytask-err"],
                c["rs274-err"], c["both-err"], lm, c["subroutine"], c["rs274-hang"], pct]
        print("%-58s %s" % (name[-58:], " ".join("%7s" % v for v in vals)))

    for g, rs in by.items():
        line(g, rs)
    line("TOTAL", [r for _, r in rows])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dirs", nargs="*", help="directories of .ngc files (default: the "
                    "linuxcnc-uspace package's files)")
    ap.add_argument("--hytask", default=os.environ.get(
        "HYTASK_BIN", os.path.join(REPO, "target", "debug", "hytask")))
    ap.add_argument("--timeout", type=float, default=60.0,
                    help="hang guard per interpreter run, seconds (default 60)")
    ap.add_argument("--list", action="store_true", help="one line per program")
    ap.add_argument("--only", choices=CLASSES, help="with --list: only this class")
    a = ap.parse_args()
    DIR_ROOTS[:] = [os.path.abspath(d) for d in a.dirs]
    files = [os.path.abspath(f) for d in a.dirs for f in dir_files(d)] if a.dirs \
        else package_files()
    rows = []
    with tempfile.TemporaryDirectory(prefix="ncfiles-diff-") as tmp:
        for f in files:
            r = classify(f, a.hytask, a.timeout, tmp)
            rows.append((group_of(f, DIR_ROOTS), r))
            if a.list and (a.only is None or a.only == r["class"]):
                extra = ""
                if r["class"] == "same" and not r.get("calls"):
                    extra = "  [calls differ] " + r.get("first", "")
                elif r["class"] == "same" and not r.get("bytes"):
                    extra = "  [bytes differ]"
                elif r["class"] == "differ":
                    extra = "  " + r.get("first", "")
                elif r["class"] == "hytask-err":
                    extra = "  " + r["hytask"].replace("\n", " | ")
                elif r["class"] == "rs274-err":
                    extra = "  " + r["rs274"]
                elif r["class"] == "both-err":
                    extra = "  line %s | rs274: %s | hytask: %s" % (
                        {True: "match", False: "differs", None: "in a called file"}[
                            r.get("line_match")], r["rs274"], r["hytask"].replace("\n", " "))
                print("%-10s %s%s" % (r["class"], f, extra), flush=True)
    table(rows, "%d programs (%s)" % (len(rows), ", ".join(a.dirs) or PACKAGE))
    c = collections.Counter(r["class"] for _, r in rows)
    acc = c["same"] + c["differ"] + c["hytask-err"]
    if acc:
        print("\nsame motion on %d of %d programs rs274 accepts (%.1f %%)"
              % (c["same"], acc, 100.0 * c["same"] / acc))


if __name__ == "__main__":
    main()
