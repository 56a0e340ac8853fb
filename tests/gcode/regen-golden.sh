#!/usr/bin/env bash
# Regenerates tests/gcode/golden/*.canon (and *.err for programs rs274 rejects) from
# LinuxCNC's rs274 (Debian package linuxcnc-uspace). Run from anywhere; needs rs274 on PATH.
# Every corpus program runs with the corpus tool table, from the corpus directory (so
# `o<name> call` finds name.ngc there, as it does for hytask). A program with a var file
# beside it (NAME.var) runs with `-v` on a copy of it; the copy rs274 writes back at exit is
# kept as golden/NAME.var. A program with an ini file beside it (NAME.ini: the embedded-Python
# programs py_*.ngc, whose [PYTHON] section names the TOPLEVEL) runs with `-i NAME.ini`.
#
#   regen-golden.sh              regenerates every golden
#   regen-golden.sh NAME.ngc...  (re)generates only these programs' goldens (new corpus
#                                files), leaving every other golden untouched
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cd "$here/corpus"
mkdir -p "$here/golden"
if [ "$#" -eq 0 ]; then
    rm -f "$here"/golden/*.canon "$here"/golden/*.err "$here"/golden/*.var
    set -- *.ngc
fi
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
for f in "$@"; do
    f="$(basename "$f")"
    name="${f%.ngc}"
    rm -f "$here/golden/$name.canon" "$here/golden/$name.err" "$here/golden/$name.var"
    vars=()
    if [ -f "$name.var" ]; then
        cp "$name.var" "$tmp/$name.var"
        vars=(-v "$tmp/$name.var")
    fi
    ini=()
    if [ -f "$name.ini" ]; then
        ini=(-i "$name.ini")
    fi
    set +e
    rs274 -t tool.tbl "${ini[@]}" "${vars[@]}" -g "$f" >"$here/golden/$name.canon" 2>"$here/golden/$name.stderr"
    rc=$?
    set -e
    if [ -f "$name.var" ] && [ "$rc" -eq 0 ]; then
        cp "$tmp/$name.var" "$here/golden/$name.var"
    fi
    if [ "$rc" -ne 0 ]; then
        # (paths below the corpus directory as relative ones: Python tracebacks name files)
        grep -v '^executing$' "$here/golden/$name.stderr" | sed "s|$PWD/||g" >"$here/golden/$name.err" || true
    fi
    rm -f "$here/golden/$name.stderr"
done
echo "regenerated $(ls "$here"/golden/*.canon | wc -l) goldens, $(ls "$here"/golden/*.err 2>/dev/null | wc -l) rejections"
