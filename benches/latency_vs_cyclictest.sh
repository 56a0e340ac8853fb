#!/usr/bin/env bash
# Side-by-side wake-up latency: `hytask latency` (the real periodic activity) against
# cyclictest, run at the same time, same period and priority, pinned to different CPUs, then
# swapped; plus A/A windows (cyclictest against cyclictest) whose spread is the noise band.
# Method: /work/shared/notes/rt-measurement.md. Needs root (SCHED_FIFO, mlockall), 2 CPUs,
# cyclictest (rt-tests) and a release build: cargo build --release --bin hytask
#
# Usage: benches/latency_vs_cyclictest.sh [window_seconds=20] [periods_us="1000 250"]
#        benches/latency_vs_cyclictest.sh --summarize DIR   (re-summarise earlier raw outputs)
# Output: one row per window with both tools' p50/p90/p99/max (µs, from 1 µs histograms,
# summarised by the same code) and the p50/p90/p99 ratios, then pooled tail counts.
set -euo pipefail
cd "$(dirname "$0")/.."
summarize() {
  python3 - "$1" <<'PY'
import re, sys
def hist(path):
    h, over = {}, 0
    for line in open(path):
        m = re.match(r'^(\d{6}) (\d+)\s*$', line)
        if m:
            h[int(m.group(1))] = h.get(int(m.group(1)), 0) + int(m.group(2))
        m = re.match(r'^# Histogram Overflows: (\d+)', line)
        if m:
            over += int(m.group(1))
    return h, over
def q(h, over, p):
    n = sum(h.values()) + over
    acc = 0
    for k in sorted(h):
        acc += h[k]
        if acc >= p * n:
            return k
    return float('inf')
def above(h, over, us):
    return sum(c for k, c in h.items() if k > us) + over
def tool(path):
    return 'hytask' if '_hytask_' in path.split('/')[-1] else 'cyclictest'
rows, pooled = [], {}
print(f"{'window':34} {'A p50/p90/p99/max':>22} {'B p50/p90/p99/max':>22} {'hytask/cyc (A/A: A/B) p50 p90 p99':>36}")
import glob, os
for fa in sorted(glob.glob(os.path.join(sys.argv[1], '*_A_*.txt')), key=lambda f: (-int(re.search(r'/p(\d+)_', f).group(1)), f)):
    fb = glob.glob(fa.split('_A_')[0] + '_B_*.txt')[0]
    tag = os.path.basename(fa).split('_A_')[0]
    P = int(re.match(r'p(\d+)_', tag).group(1))
    stats = []
    for f in (fa, fb):
        h, over = hist(f)
        mx = max([k for k in h if h[k]] or [0]) if not over else float('inf')
        s = [q(h, over, x) for x in (0.5, 0.9, 0.99)] + [mx]
        stats.append(s)
        key = (P, tool(f), 'AA' if tool(fa) == tool(fb) else 'AB')
        c = pooled.setdefault(key, [0, 0, 0, 0])
        c[0] += sum(h.values()) + over; c[1] += above(h, over, 50); c[2] += above(h, over, 100); c[3] += above(h, over, P / 2)
    num, den = (stats[1], stats[0]) if (tool(fa), tool(fb)) == ('cyclictest', 'hytask') else (stats[0], stats[1])
    r = [f"{a / b:.2f}" if b else "-" for a, b in zip(num[:3], den[:3])]
    fmt = lambda s: "/".join(str(x) for x in s)
    print(f"{tag:34} {fmt(stats[0]):>22} {fmt(stats[1]):>22} {' '.join(r):>36}")
print()
print(f"{'period_us':>9} {'tool':>10} {'windows':>7} {'samples':>9} {'>50us':>7} {'>100us':>7} {'>P/2':>7}")
for (P, t, kind), c in sorted(pooled.items()):
    print(f"{P:>9} {t:>10} {kind:>7} {c[0]:>9} {c[1]:>7} {c[2]:>7} {c[3]:>7}")
PY
}

if [ "${1:-}" = --summarize ]; then summarize "$2"; exit; fi
WIN=${1:-20}
PERIODS=${2:-"1000 250"}
PRIO=80
HYTASK=${HYTASK:-target/release/hytask}
OUT=${OUT:-target/latency-$(date -u +%Y%m%dT%H%M%S)}
mkdir -p "$OUT"
command -v cyclictest >/dev/null || { echo "cyclictest not found (apt install rt-tests)" >&2; exit 1; }
[ -x "$HYTASK" ] || { echo "$HYTASK missing: cargo build --release --bin hytask" >&2; exit 1; }

cyc() { # period cpu file
  cyclictest -m -p "$PRIO" -i "$1" -t 1 -a "$2" -q --histogram=20000 -D "$WIN" > "$3" 2>&1
}
hyt() { # period cpu file
  "$HYTASK" latency --period-us "$1" --priority "$PRIO" --duration "${WIN}s" --cpu "$2" --histogram > "$3" 2>&1
}

for P in $PERIODS; do
  for layout in "hytask:0 cyclictest:1" "cyclictest:0 hytask:1" "cyclictest:0 cyclictest:1" "hytask:1 cyclictest:0"; do
    set -- $layout
    a=${1%%:*}; ca=${1##*:}; b=${2%%:*}; cb=${2##*:}
    tag="p${P}_${a}${ca}_${b}${cb}"
    echo "window $tag (${WIN}s)..." >&2
    fa="$OUT/${tag}_A_${a}_cpu${ca}.txt"; fb="$OUT/${tag}_B_${b}_cpu${cb}.txt"
    if [ "$a" = hytask ]; then hyt "$P" "$ca" "$fa" & else cyc "$P" "$ca" "$fa" & fi
    pa=$!
    if [ "$b" = hytask ]; then hyt "$P" "$cb" "$fb" & else cyc "$P" "$cb" "$fb" & fi
    pb=$!
    wait "$pa" "$pb"
  done
done

summarize "$OUT"
echo "raw outputs in $OUT" >&2
