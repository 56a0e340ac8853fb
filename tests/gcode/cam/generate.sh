#!/usr/bin/env bash
# Regenerates the real-CAM corpus programs tests/gcode/corpus/cam_dxf2gcode_*.ngc from the
# drawings written by make-dxf.py (drawn for this repository, millimetres) with Debian's
# dxf2gcode (`apt-get install dxf2gcode`, version 20191025; its default post-processor
# "G-CODE for LinuxCNC"), then their rs274 goldens. Not run by CI: the outputs are
# committed, and CI checks them against the goldens and a live rs274.
#
# Two settings per drawing:
#   cam_dxf2gcode_NAME.ngc       dxf2gcode's defaults: the tool follows the contour (G40)
#   cam_dxf2gcode_NAME_comp.ngc  automatic cutter compensation (G41/G42 by the control,
#                                dxf2gcode's "done by machine"), tool 1 of 6.35 mm (T1 of
#                                the corpus tool table), lead-in radius 5 mm
# dxf2gcode 20191025 needs dxf2gcode-py3.py on Python >= 3.10.
#
#   tests/gcode/cam/generate.sh
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
corpus="$here/../corpus"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
mkdir -m 700 "$tmp/xdg"
mkdir "$tmp/plain" "$tmp/comp"
python3 "$here/make-dxf.py" "$tmp"
names=()

# run HOME NAME OUT: one export; HOME holds dxf2gcode's configuration (.config/dxf2gcode),
# written with its defaults on the first run.
run() {
    (cd "$tmp" && HOME="$1" QT_QPA_PLATFORM=offscreen XDG_RUNTIME_DIR="$tmp/xdg" \
        /usr/bin/python3 "$here/dxf2gcode-py3.py" -q -e "$3.ngc" "$2.dxf" >"$3.log" 2>&1) ||
        { cat "$tmp/$3.log"; exit 1; }
    # The "(Time: …)" comment is dropped so that a regeneration changes nothing.
    grep -v '^(Time: ' "$tmp/$3.ngc" >"$corpus/$3.ngc"
    names+=("$3.ngc")
}

for dxf in "$tmp"/*.dxf; do
    n="$(basename "$dxf" .dxf)"
    run "$tmp/plain" "$n" "cam_dxf2gcode_$n"
done
mkdir -p "$tmp/comp/.config"
cp -r "$tmp/plain/.config/dxf2gcode" "$tmp/comp/.config/"
cfg="$tmp/comp/.config/dxf2gcode/config/config.cfg"
sed -i -e 's/automatic_cutter_compensation = False/automatic_cutter_compensation = True/' \
    -e '/\[\[1\]\]/,/start_radius/ s/diameter = .*/diameter = 6.35/' \
    -e '/\[\[1\]\]/,/start_radius/ s/start_radius = .*/start_radius = 5.0/' "$cfg"
grep -q 'automatic_cutter_compensation = True' "$cfg"
for dxf in "$tmp"/*.dxf; do
    n="$(basename "$dxf" .dxf)"
    run "$tmp/comp" "$n" "cam_dxf2gcode_${n}_comp"
done
"$here/../regen-golden.sh" "${names[@]}"
