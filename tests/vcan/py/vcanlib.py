"""Shared helpers of the python peer tests (run by tests/vcan/suite, on vcan0).

Under qemu's software emulation everything is several times slower than on a host:
python-canopen's timeouts are relaxed (RELAX) rather than checks skipped, and peers are
waited for on their own "ready" line, never with a fixed sleep.
"""
import os
import subprocess
import sys
import threading
import time

import canopen
from canopen import objectdictionary as odm

IFACE = os.environ.get("HYTASK_VCAN", "vcan0")
HYTASK = os.environ.get("HYTASK_BIN", "target/debug/hytask")
RELAX = 10.0  # python-canopen timeouts x RELAX under emulation
HANG_GUARD = 120.0  # seconds: only a guard against hangs, never a timing assertion

failures = []


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what, flush=True)
    if not cond:
        failures.append(what)


def finish(name):
    if failures:
        print(f"{name}: {len(failures)} check(s) failed: {failures}", flush=True)
        sys.exit(1)
    print(f"{name}: all checks passed", flush=True)
    sys.exit(0)


def relax_timeouts(node):
    node.sdo.RESPONSE_TIMEOUT = 0.3 * RELAX
    if isinstance(node, canopen.BaseNode402):
        for t in ("TIMEOUT_RESET_FAULT", "TIMEOUT_SWITCH_OP_MODE", "TIMEOUT_SWITCH_STATE_FINAL",
                  "TIMEOUT_SWITCH_STATE_SINGLE", "TIMEOUT_CHECK_TPDO"):
            setattr(node, t, getattr(canopen.BaseNode402, t) * RELAX)


def wait_for(cond, what, guard=HANG_GUARD):
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > guard:
            raise TimeoutError(f"hang guard: {what} not seen in {guard} s")
        time.sleep(0.01)


class Proc:
    """A child process whose stdout is collected; wait_line() waits for a line."""

    def __init__(self, args):
        self.args = args
        self.p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  text=True, bufsize=1)
        self.lines = []
        self.t = threading.Thread(target=self._pump, daemon=True)
        self.t.start()

    def _pump(self):
        for line in self.p.stdout:
            print(f"  [{os.path.basename(self.args[0])}] {line.rstrip()}", flush=True)
            self.lines.append(line.rstrip())

    def wait_line(self, prefix):
        wait_for(lambda: any(l.startswith(prefix) for l in self.lines) or self.p.poll() is not None,
                 f"{prefix!r} from {self.args}")
        if not any(l.startswith(prefix) for l in self.lines):
            raise RuntimeError(f"{self.args} exited {self.p.returncode} before {prefix!r}")

    def stop(self):
        if self.p.poll() is None:
            self.p.terminate()
        try:
            return self.p.wait(timeout=HANG_GUARD)
        finally:
            self.t.join(timeout=5)


def hytask(*args):
    """Runs `hytask ARGS`; returns (exit code, stdout+stderr)."""
    r = subprocess.run([HYTASK, *args], capture_output=True, text=True, timeout=HANG_GUARD)
    out = (r.stdout + r.stderr).strip()
    print(f"  $ hytask {' '.join(args)} -> {r.returncode}: {out}", flush=True)
    return r.returncode, out


def var(name, index, sub, dtype, access="rw", default=None, pdo=False):
    v = odm.ODVariable(name, index, sub)
    v.data_type = dtype
    v.access_type = access
    v.pdo_mappable = pdo
    if default is not None:
        v.default = default
    return v


def record(name, index, members):
    r = odm.ODRecord(name, index)
    for m in members:
        r.add_member(m)
    return r


def drive_od():
    """The object dictionary of hytask's loopback CiA 402 drive (`hytask sim-drive`), as a
    master sees it: what a vendor's EDS file would describe."""
    od = odm.ObjectDictionary()
    U8, U16, U32, I8, I32 = odm.UNSIGNED8, odm.UNSIGNED16, odm.UNSIGNED32, odm.INTEGER8, odm.INTEGER32
    od.add_object(var("Device type", 0x1000, 0, U32, "ro"))
    od.add_object(var("Error register", 0x1001, 0, U8, "ro"))
    od.add_object(var("Device name", 0x1008, 0, odm.VISIBLE_STRING, "const"))
    od.add_object(var("Producer heartbeat time", 0x1017, 0, U16))
    od.add_object(record("Identity", 0x1018, [
        var("Highest sub-index", 0x1018, 0, U8, "const"),
        var("Vendor-ID", 0x1018, 1, U32, "ro"),
        var("Product code", 0x1018, 2, U32, "ro"),
        var("Revision number", 0x1018, 3, U32, "ro"),
        var("Serial number", 0x1018, 4, U32, "ro")]))
    for k in range(4):
        for base, rx in ((0x1400, True), (0x1800, False)):
            i = base + k
            subs = [var("Highest sub-index", i, 0, U8, "const"),
                    var("COB-ID", i, 1, U32),
                    var("Transmission type", i, 2, U8)]
            if not rx:
                subs += [var("Inhibit time", i, 3, U16), var("Event timer", i, 5, U16)]
            od.add_object(record(("RPDO" if rx else "TPDO") + f"{k + 1} communication", i, subs))
            m = i + 0x200
            od.add_object(record(("RPDO" if rx else "TPDO") + f"{k + 1} mapping", m,
                                 [var("Number of entries", m, 0, U8)] +
                                 [var(f"Mapping {s}", m, s, U32) for s in range(1, 9)]))
    od.add_object(record("Fault injection", 0x2000, [
        var("Highest sub-index", 0x2000, 0, U8, "const"),
        var("Drive fault", 0x2000, 1, U16),
        var("Stop heartbeat", 0x2000, 2, U8),
        var("Send EMCY", 0x2000, 3, U16)]))
    od.add_object(var("Domain", 0x2001, 0, odm.DOMAIN))
    od.add_object(var("Error code", 0x603F, 0, U16, "ro", pdo=True))
    od.add_object(var("Controlword", 0x6040, 0, U16, "rw", pdo=True))
    od.add_object(var("Statusword", 0x6041, 0, U16, "ro", pdo=True))
    od.add_object(var("Modes of operation", 0x6060, 0, I8, "rw", pdo=True))
    od.add_object(var("Modes of operation display", 0x6061, 0, I8, "ro", pdo=True))
    od.add_object(var("Position actual value", 0x6064, 0, I32, "ro", pdo=True))
    od.add_object(var("Following error window", 0x6065, 0, U32))
    od.add_object(var("Velocity actual value", 0x606C, 0, I32, "ro", pdo=True))
    od.add_object(var("Target position", 0x607A, 0, I32, "rw", pdo=True))
    od.add_object(var("Homing method", 0x6098, 0, I8))
    od.add_object(var("Home offset", 0x607C, 0, I32))
    od.add_object(record("Homing speeds", 0x6099, [
        var("Highest sub-index", 0x6099, 0, U8, "const"),
        var("Speed during search for switch", 0x6099, 1, U32),
        var("Speed during search for zero", 0x6099, 2, U32)]))
    od.add_object(var("Homing acceleration", 0x609A, 0, U32))
    od.add_object(record("Simulated switches", 0x2002, [
        var("Highest sub-index", 0x2002, 0, U8, "const"),
        var("Home switch", 0x2002, 1, I32),
        var("Negative limit switch", 0x2002, 2, I32),
        var("Positive limit switch", 0x2002, 3, I32)]))
    od.add_object(var("Target velocity", 0x60FF, 0, I32, "rw", pdo=True))
    od.add_object(var("Supported drive modes", 0x6502, 0, U32, "ro"))
    return od


def network():
    net = canopen.Network()
    net.connect(interface="socketcan", channel=IFACE)
    return net


def domain_default():
    """The initial value of the loopback drive's domain object 0x2001 (od::domain_default)."""
    return bytes((i * 7 + 3) % 256 for i in range(1000))


class SdoWatch:
    """Records the command byte of every SDO request to `node` (COB 0x600 + node) and of
    every response from it (0x580 + node) that another process put on the bus (python-can
    does not receive its own frames), to tell which protocol a transfer used."""

    def __init__(self, net, node):
        self.req, self.resp = [], []
        net.subscribe(0x600 + node, lambda _id, data, _ts: self.req.append(data[0]))
        net.subscribe(0x580 + node, lambda _id, data, _ts: self.resp.append(data[0]))

    def take(self, until=None):
        """(requests, responses) since the last call.

        When another process ends a transfer, its last frame can still be on its way
        through python-can's receive thread when that process exits. `until(req, resp)`
        names the frame that ends the transfer; it is waited for (up to 20 s, a guard,
        never a timing assertion), so that it is neither missed here nor left over for
        the next call or for python-canopen's own SDO client, which sees the same
        responses."""
        if until is not None:
            try:
                wait_for(lambda: until(self.req, self.resp), "the transfer's last SDO frame", guard=20.0)
            except TimeoutError:
                pass  # the caller's check reports what is missing
        r = (self.req, self.resp)
        self.req, self.resp = [], []
        return r
