#!/usr/bin/env bash
# Planner side by side with LinuxCNC 2.9 (issue 14): generates the benchmark programs
# (benches/programs/gen.rs), plans each with `hytask plan` at the default limits (50 mm/s,
# 500 mm/s², 50,000 mm/s³, 1 ms), runs each in LinuxCNC (linuxcnc-uspace, headless: a
# Python front end instead of a GUI, trivkins XYZ, MAX_VELOCITY 50 and MAX_ACCELERATION
# 500 for [TRAJ], every [AXIS_*] and [JOINT_*], 1 ms servo period, each program's own G64),
# samples the joint position commands every servo period with sampler/halsampler and takes
# LinuxCNC's time from the trace: from the last period at rest before motion to the first at
# rest after it. Prints one table: program, LinuxCNC time, hytask planned time, ratio, lower
# bound (motion::bounds, time-optimal on hytask's planned path).
#
#   bash benches/planner_vs_linuxcnc.sh [--no-linuxcnc] [--no-cam]
#
# Besides the generated programs: two dxf2gcode outputs of the corpus and three opencamlib
# 3D surfacing programs made at run time (PyPI opencamlib 2023.1.11 in target/planner-cam-venv,
# installed on first use; --no-cam leaves them out). Without linuxcnc (or with --no-linuxcnc)
# the LinuxCNC column shows "n/a". The uspace
# servo thread runs without realtime privileges here; the measured time counts servo
# periods, not wall time, so a loaded machine makes the run slower but not the result
# different (lost samples are counted and reported).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
work=${PLANNER_VS_LINUXCNC_DIR:-$root/target/planner-vs-linuxcnc}
rm -rf "$work"
mkdir -p "$work/programs" "$work/lcnc" "$work/out"

cargo build -q --workspace --bin hytask --example planner_programs
"$root/target/debug/examples/planner_programs" "$work/programs" >/dev/null
programs=(square spiral sine trochoidal)

# Real CAM output (issue 14's "larger set of real CAM files"). dxf2gcode's contour cuts of
# two drawings of tests/gcode/cam (committed in the corpus; the plate, 212 s of mostly
# F150/F400 cutting, is left out to keep the run short; the _comp variants differ only by
# G41/G42). Then dense 3D surfacing from opencamlib, generated here in a venv under target/
# with a pinned version (benches/programs/ocl_programs.py; --no-cam skips it).
for n in bracket cam; do
    cp "$root/tests/gcode/corpus/cam_dxf2gcode_$n.ngc" "$work/programs/"
    programs+=("cam_dxf2gcode_$n")
done
cam=1
for a in "$@"; do [[ $a == --no-cam ]] && cam=0; done
if ((cam)); then
    venv=$root/target/planner-cam-venv
    if ! "$venv/bin/python" -c 'import opencamlib' 2>/dev/null; then
        python3 -m venv "$venv"
        "$venv/bin/python" -m pip install -q opencamlib==2023.1.11
    fi
    # opencamlib's Python bindings print a line per destroyed Waterline object.
    "$venv/bin/python" "$root/benches/programs/ocl_programs.py" "$work/programs" >/dev/null
    programs+=(ocl_dome_zigzag ocl_wave_zigzag ocl_dome_waterline)
fi
tool_table=$root/tests/gcode/corpus/tool.tbl

use_lcnc=1
for a in "$@"; do [[ $a == --no-linuxcnc ]] && use_lcnc=0; done
command -v linuxcnc >/dev/null || use_lcnc=0

if ((use_lcnc)); then
    # HAL's shared memory left by an earlier run under another user (root, mode 600) makes
    # this run, as nobody, fail with "could not open shared memory": drop it when no
    # LinuxCNC is running.
    if ! pgrep -x rtapi_app >/dev/null; then
        for key in 0x48414c32 0x48484c34; do ipcrm -M "$key" 2>/dev/null || true; done
    fi
    # rtapi_app refuses to run as root: run LinuxCNC as nobody in a directory of its own.
    cfg=$(mktemp -d /tmp/planner-vs-linuxcnc.XXXXXX)
    trap 'rm -rf "$cfg"' EXIT
    as_user=()
    if ((EUID == 0)); then
        as_user=(setpriv --reuid=65534 --regid=65534 --clear-groups)
    fi
    mkdir -p "$cfg/programs" "$cfg/out"
    cp "$work"/programs/*.ngc "$cfg/programs/"
    cp "$root/benches/planner_vs_linuxcnc/driver.py" "$cfg/driver.py"
    cp "$tool_table" "$cfg/tool.tbl"
    chmod +x "$cfg/driver.py"
    : >"$cfg/sim.var"
    axis() { # name joint
        cat <<EOF
[AXIS_$1]
MAX_VELOCITY = 50
MAX_ACCELERATION = 500
MIN_LIMIT = -1000
MAX_LIMIT = 1000

[JOINT_$2]
TYPE = LINEAR
MAX_VELOCITY = 50
MAX_ACCELERATION = 500
MIN_LIMIT = -1000
MAX_LIMIT = 1000
FERROR = 10
MIN_FERROR = 10
HOME = 0
HOME_OFFSET = 0
HOME_SEARCH_VEL = 0
HOME_LATCH_VEL = 0
HOME_SEQUENCE = 0

EOF
    }
    {
        cat <<EOF
[EMC]
VERSION = 1.1
MACHINE = hytask-bench

[DISPLAY]
DISPLAY = $cfg/driver.py

[TASK]
TASK = milltask
CYCLE_TIME = 0.001

[RS274NGC]
PARAMETER_FILE = sim.var

[EMCMOT]
EMCMOT = motmod
COMM_TIMEOUT = 4.0
SERVO_PERIOD = 1000000

[EMCIO]
EMCIO = io
CYCLE_TIME = 0.100
TOOL_TABLE = tool.tbl

[HAL]
HALFILE = bench.hal

[TRAJ]
COORDINATES = XYZ
LINEAR_UNITS = mm
ANGULAR_UNITS = degree
DEFAULT_LINEAR_VELOCITY = 50
MAX_LINEAR_VELOCITY = 50
MAX_LINEAR_ACCELERATION = 500
DEFAULT_LINEAR_ACCELERATION = 500

[KINS]
JOINTS = 3
KINEMATICS = trivkins coordinates=XYZ

EOF
        axis X 0
        axis Y 1
        axis Z 2
    } >"$cfg/bench.ini"
    cat >"$cfg/bench.hal" <<'EOF'
loadrt [KINS]KINEMATICS
loadrt [EMCMOT]EMCMOT servo_period_nsec=[EMCMOT]SERVO_PERIOD num_joints=[KINS]JOINTS
loadrt sampler depth=65536 cfg=fff
addf motion-command-handler servo-thread
addf motion-controller servo-thread
net xpos joint.0.motor-pos-cmd => joint.0.motor-pos-fb sampler.0.pin.0
net ypos joint.1.motor-pos-cmd => joint.1.motor-pos-fb sampler.0.pin.1
net zpos joint.2.motor-pos-cmd => joint.2.motor-pos-fb sampler.0.pin.2
addf sampler.0 servo-thread
setp sampler.0.enable 0
net estop-loop iocontrol.0.user-enable-out iocontrol.0.emc-enable-in
net tool-prep-loop iocontrol.0.tool-prepare iocontrol.0.tool-prepared
net tool-change-loop iocontrol.0.tool-change iocontrol.0.tool-changed
EOF
    list=""
    for p in "${programs[@]}"; do list+="$cfg/programs/$p.ngc:"; done
    chmod -R a+rwX "$cfg"
    # RUNTESTS keeps LinuxCNC's messages on stdout instead of files in $HOME.
    (cd "$cfg" && "${as_user[@]}" env HOME="$cfg" RUNTESTS=1 HYB_OUT="$cfg/out" \
        HYB_PROGRAMS="$list" timeout 1800 linuxcnc "$cfg/bench.ini") >"$work/linuxcnc.log" 2>&1 || {
        echo "linuxcnc failed, see $work/linuxcnc.log" >&2
        tail -20 "$work/linuxcnc.log" >&2
        use_lcnc=0
    }
    cp "$cfg"/out/* "$work/out/" 2>/dev/null || true
fi

# Time from the last sample at rest before motion to the first at rest after it: lines of
# `halsampler -t` are "sample x y z" (and "overrun" when the FIFO overflowed).
lcnc_time() {
    awk '$1 !~ /^[0-9]+$/ { next }
         seen && ($2 != x || $3 != y || $4 != z) { if (!first) first = prev; last = $1 }
         { seen = 1; prev = $1; x = $2; y = $3; z = $4 }
         END { if (first) printf "%.3f", (last - first) / 1000.0; else print "n/a" }' "$1"
}

printf '%-20s %12s %12s %8s %12s %10s\n' program "LinuxCNC s" "hytask s" ratio "bound s" "lost"
for p in "${programs[@]}"; do
    out=$("$root/target/debug/hytask" plan --tool-table "$tool_table" "$work/programs/$p.ngc")
    hy=$(awk '/^job time:/ { print $3 }' <<<"$out")
    lb=$(awk '/^optimal bound:/ { print $3 }' <<<"$out")
    lc=n/a lost=n/a ratio=n/a
    if ((use_lcnc)) && [[ -s $work/out/$p.samples ]]; then
        lc=$(lcnc_time "$work/out/$p.samples")
        lost=$(cat "$work/out/$p.overruns")
        ratio=$(awk -v a="$hy" -v b="$lc" 'BEGIN { printf "%.3f", a / b }')
    fi
    printf '%-20s %12s %12s %8s %12s %10s\n' "$p" "$lc" "$hy" "$ratio" "${lb:-n/a}" "$lost"
done
