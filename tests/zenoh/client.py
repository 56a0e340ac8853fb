"""An independent Zenoh peer (Eclipse's Python binding) operating hytask through its bridge.

Usage: client.py ENDPOINT MACHINE_KEY
Prints one line per step, "ok <step> <detail>", and exits non-zero at the first failure.
Every wait is a hang guard (60 s), never a timing.
"""
import json
import sys
import threading
import time

import zenoh

endpoint, machine = sys.argv[1], sys.argv[2]
prefix = f"hytask/{machine}"
GUARD = 60.0


def step(name, detail=""):
    print(f"ok {name} {detail}", flush=True)


def fail(msg):
    print(f"FAIL {msg}", flush=True)
    sys.exit(1)


conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)


def get(key, payload=None):
    """One query; returns (ok, decoded JSON) of the first reply."""
    deadline = time.time() + GUARD
    while time.time() < deadline:
        replies = list(session.get(key, payload=payload, timeout=GUARD))
        if replies:
            r = replies[0]
            if r.ok is not None:
                return True, json.loads(r.ok.payload.to_bytes())
            return False, json.loads(r.err.payload.to_bytes())
        time.sleep(0.2)  # the route to the queryable is not known yet
    fail(f"no reply to {key}")


def call(key, args=None):
    ok, v = get(key, json.dumps(args) if args is not None else None)
    return ok, v


# Subscriptions first: status (periodic) and the mode events of the control stream.
status_seen = threading.Event()
modes = []


def on_status(sample):
    status_seen.set()


def on_mode(sample):
    modes.append(json.loads(sample.payload.to_bytes()))


subs = [
    session.declare_subscriber(f"{prefix}/status", on_status),
    session.declare_subscriber(f"{prefix}/events/mode", on_mode),
]
if not status_seen.wait(GUARD):
    fail("no status publication")
step("status-subscription")

ok, tasks = get(f"{prefix}/tasks")
if not ok:
    fail(f"tasks: {tasks}")
names = [t["name"] for t in tasks["result"]]
if "machine" not in names or "axis.X" not in names:
    fail(f"tasks: {names}")
step("tasks", ",".join(names))

ok, st = get(f"{prefix}/status")
if not ok:
    fail(f"status: {st}")
if st["result"]["mode"] == "estop":
    ok, r = call(f"{prefix}/machine/op/estop_reset")
    if not ok:
        fail(f"estop_reset: {r}")
# An operation as a command: accepted, done when every drive is operational.
ok, r = call(f"{prefix}/machine/op/machine_on")
if not ok or r["status"] != "done":
    fail(f"machine_on: {r}")
step("operation", json.dumps(r))

# A control method (the same as on the socket): home, then wait for every axis homed.
ok, r = call(f"{prefix}/control/home")
if not ok:
    fail(f"home: {r}")
deadline = time.time() + GUARD * 2
while True:
    ok, st = get(f"{prefix}/status")
    if ok and all(a["homed"] for a in st["result"]["axes"]) and st["result"]["mode"] == "idle":
        break
    if time.time() > deadline:
        fail(f"not homed: {st}")
    time.sleep(0.1)
step("homed")

# A port: the X axis' feedback, read by query (latest published value).
deadline = time.time() + GUARD
while True:
    ok, fb = get(f"{prefix}/axis.X/port/axis.X.feedback")
    if ok and fb["result"]["homed"]:
        break
    if time.time() > deadline:
        fail(f"port: {fb}")
    time.sleep(0.1)
step("port", json.dumps(fb["result"]))

# A rejected call comes back as an error reply with its reason.
ok, r = call(f"{prefix}/control/job.run")
if ok or r["status"] != "rejected":
    fail(f"job.run without a job: {ok} {r}")
step("rejected", r["error"])

deadline = time.time() + GUARD
while not any(m.get("mode") == "idle" for m in modes):
    if time.time() > deadline:
        fail(f"no mode event: {modes}")
    time.sleep(0.1)
step("events", json.dumps(modes))

for s in subs:
    s.undeclare()
session.close()
step("done")
