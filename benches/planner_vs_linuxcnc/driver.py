#!/usr/bin/python3
"""Non-GUI front end for LinuxCNC (the INI's [DISPLAY] DISPLAY): homes the machine, then
for every program in $HYB_PROGRAMS (colon-separated) goes back to X0 Y0 Z0, starts
`halsampler -t` on the servo-thread sampler (joint position commands X Y Z, one line per
servo period), runs the program in AUTO, waits until the interpreter is idle and motion has
stopped, stops the sampler and writes the samples to $HYB_OUT/<program>.samples, with the
sampler's overrun count (lost samples) in <program>.overruns. Exiting ends LinuxCNC.

Written for hytask's planner benchmark (benches/planner_vs_linuxcnc.sh)."""

import os
import subprocess
import sys
import time

import linuxcnc

TIMEOUT_S = 900.0


def wait(pred, what, timeout=60.0):
    s = linuxcnc.stat()
    t0 = time.time()
    while True:
        s.poll()
        if pred(s):
            return s
        if time.time() - t0 > timeout:
            sys.exit("driver: timed out waiting for " + what)
        time.sleep(0.01)


def setp(pin, value):
    subprocess.run(["halcmd", "setp", pin, value], check=True)


def main():
    out = os.environ["HYB_OUT"]
    programs = [p for p in os.environ["HYB_PROGRAMS"].split(":") if p]
    c = linuxcnc.command()
    c.state(linuxcnc.STATE_ESTOP_RESET)
    c.state(linuxcnc.STATE_ON)
    wait(lambda s: s.task_state == linuxcnc.STATE_ON, "machine on")
    c.mode(linuxcnc.MODE_MANUAL)
    c.wait_complete()
    c.home(-1)
    wait(lambda s: all(s.homed[j] for j in range(s.joints)), "homing")
    for prog in programs:
        name = os.path.splitext(os.path.basename(prog))[0]
        c.mode(linuxcnc.MODE_MDI)
        c.wait_complete()
        c.mdi("G21 G90 G0 X0 Y0 Z0")
        c.wait_complete(60)
        wait(lambda s: s.interp_state == linuxcnc.INTERP_IDLE and s.queue == 0
             and s.current_vel == 0.0, "return to origin")
        before = subprocess.run(["halcmd", "getp", "sampler.0.overruns"],
                                capture_output=True, text=True).stdout.strip()
        # The sampler records only while enabled, so the file holds this program alone
        # (not the return move, nor what queued up while nobody read the FIFO).
        samples = open(os.path.join(out, name + ".samples"), "w")
        sampler = subprocess.Popen(["halsampler", "-t"], stdout=samples)
        time.sleep(0.5)
        setp("sampler.0.enable", "1")
        c.mode(linuxcnc.MODE_AUTO)
        c.wait_complete()
        c.program_open(prog)
        c.auto(linuxcnc.AUTO_RUN, 0)
        wait(lambda s: s.interp_state != linuxcnc.INTERP_IDLE, "program start", 10.0)
        wait(lambda s: s.interp_state == linuxcnc.INTERP_IDLE and s.queue == 0
             and s.current_vel == 0.0, "program end", TIMEOUT_S)
        time.sleep(0.3)
        setp("sampler.0.enable", "0")
        time.sleep(0.5)
        sampler.terminate()
        sampler.wait()
        samples.close()
        after = subprocess.run(["halcmd", "getp", "sampler.0.overruns"],
                               capture_output=True, text=True).stdout.strip()
        with open(os.path.join(out, name + ".overruns"), "w") as f:
            f.write("%d\n" % (int(after or 0) - int(before or 0)))
        print("driver: ran", prog, flush=True)
    c.state(linuxcnc.STATE_OFF)


if __name__ == "__main__":
    main()
