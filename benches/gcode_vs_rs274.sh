#!/usr/bin/env bash
# Interpreter throughput: `hytask gcode canon` vs LinuxCNC's `rs274 -g` on the same large
# program (generated here into target/gcode-bench/, never committed), both writing to
# /dev/null, measured side by side with hyperfine (apt install hyperfine). Release build.
#
#   benches/gcode_vs_rs274.sh [lines]      (default 150000 lines; RUNS=n to change runs;
#                                           HYTASK_BIN=path to time a given build)
set -euo pipefail
cd "$(dirname "$0")/.."
lines="${1:-150000}"
out=target/gcode-bench
mkdir -p "$out"
prog="$out/large.ngc"

command -v rs274 >/dev/null || { echo "rs274 not found (apt install linuxcnc-uspace)"; exit 1; }
command -v hyperfine >/dev/null || { echo "hyperfine not found (apt install hyperfine)"; exit 1; }

# HYTASK_BIN=path times an already built binary instead (e.g. two builds side by side).
if [ -z "${HYTASK_BIN:-}" ]; then
  cargo build --release --quiet
fi
hy="${HYTASK_BIN:-target/release/hytask}"
tbl=tests/gcode/corpus/tool.tbl

# CAM-style program: raster of short G1 moves, arcs, and a drilling block with a tool
# change every ~5000 lines.
awk -v n="$lines" 'BEGIN {
  print "G21 G90 G94 G17 G64 P0.01"; print "F1500 S10000 M3"; print "G0 X0 Y0 Z5"; print "G1 Z-1";
  i = 0; k = 0;
  while (i < n) {
    if (i % 5000 == 0) {
      printf "M5\nT%d M6\nS%d M3\nG0 Z5\n", (k % 2) + 1, 8000 + k; k++;
      printf "G98 G81 X10 Y10 Z-3 R1 F200\nX20\nX30\nY20\nX20\nG80\nG1 Z-1 F1500\n"; i += 11; continue;
    }
    if (i % 50 == 49) { printf "G2 X%.4f Y%.4f I2 J0\n", x + 4, y; x += 4; i++; continue; }
    x = 50 * sin(i * 0.001); y = 50 * cos(i * 0.0013);
    printf "G1 X%.4f Y%.4f Z%.4f\n", x, y, -1 - 0.5 * sin(i * 0.01); i++;
  }
  print "G0 Z5"; print "M5"; print "M2";
}' >"$prog"
total=$(wc -l <"$prog")
echo "program: $prog ($total lines, $(du -h "$prog" | cut -f1))"

# Sanity: both accept it and produce the same calls (prefix columns stripped).
strip() { sed -E 's/^ *[0-9]+ N[^ ]* +//'; }
if diff -q <(rs274 -t $tbl -g "$prog" 2>/dev/null | strip) <("$hy" gcode canon --tool-table $tbl "$prog" | strip) >/dev/null; then
  echo "traces identical"
else
  echo "WARNING: traces differ on the benchmark program"
fi

# HYTASK_BASE=path adds an earlier build to the same run (before/after an optimisation).
base=()
if [ -n "${HYTASK_BASE:-}" ]; then
  base=(-n hytask-base "$HYTASK_BASE gcode canon --tool-table $tbl $prog > /dev/null")
fi
hyperfine --warmup 2 --runs "${RUNS:-10}" --export-json "$out/result.json" \
  -n hytask "$hy gcode canon --tool-table $tbl $prog > /dev/null" \
  "${base[@]}" \
  -n rs274 "rs274 -t $tbl -g $prog > /dev/null 2>&1"

python3 - "$out/result.json" "$total" <<'PY'
import json, sys
r = {x["command"]: x for x in json.load(open(sys.argv[1]))["results"]}
n = int(sys.argv[2])
h, s = r["hytask"]["mean"], r["rs274"]["mean"]
print(f"hytask: {n / h / 1e6:.2f} M lines/s   rs274: {n / s / 1e6:.3f} M lines/s   ratio: {s / h:.1f}x")
for name, x in r.items():
    u = x["user"] + x["system"]
    print(f"  {name}: mean {x['mean'] * 1e3:.1f} ms, user+sys {u * 1e3:.1f} ms, wall ratio {s / x['mean']:.1f}x, "
          f"CPU ratio {(r['rs274']['user'] + r['rs274']['system']) / u:.1f}x")
PY
