"""hytask's CANopen master side (`hytask canopen`: SDO client, NMT, heartbeat consumer)
against an independent slave: a python-canopen LocalNode on vcan0."""
import time

import canopen
from canopen import objectdictionary as odm

from vcanlib import check, finish, hytask, network, var, record, wait_for, IFACE

NODE = 5
NAME = "python-canopen LocalNode peer"


def peer_od():
    od = odm.ObjectDictionary()
    od.add_object(var("Device type", 0x1000, 0, odm.UNSIGNED32, "ro", default=0x00000191))
    od.add_object(var("Device name", 0x1008, 0, odm.VISIBLE_STRING, "ro", default=NAME))
    od.add_object(var("Producer heartbeat time", 0x1017, 0, odm.UNSIGNED16, "rw", default=0))
    od.add_object(record("Identity", 0x1018, [
        var("Highest sub-index", 0x1018, 0, odm.UNSIGNED8, "const", default=1),
        var("Vendor-ID", 0x1018, 1, odm.UNSIGNED32, "ro", default=0x12345678)]))
    od.add_object(var("Setpoint", 0x2001, 0, odm.UNSIGNED32, "rw", default=0))
    od.add_object(var("Label", 0x2002, 0, odm.VISIBLE_STRING, "rw", default=""))
    od.add_object(var("Offset", 0x2003, 0, odm.INTEGER16, "rw", default=-5))
    return od


def main():
    net = network()
    node = canopen.LocalNode(NODE, peer_od())
    net.add_node(node)
    node.nmt.state = "PRE-OPERATIONAL"
    node.nmt.start_heartbeat(100)
    t = ["--iface", IFACE, "--timeout-ms", "5000"]
    try:
        rc, out = hytask("canopen", *t, "scan")
        check(rc == 0 and f"node {NODE}: device type 91 01 00 00" in out and "1 node(s)" in out,
              "scan finds exactly the peer with its device type")
        rc, out = hytask("canopen", *t, "sdo-read", "--node", str(NODE), "0x1018", "1", "--type", "u32")
        check(rc == 0 and out == str(0x12345678), "expedited SDO read of 0x1018:1")
        rc, out = hytask("canopen", *t, "sdo-read", "--node", str(NODE), "0x1008", "--type", "str")
        check(rc == 0 and out == NAME, "segmented SDO read of 0x1008")
        rc, out = hytask("canopen", *t, "sdo-read", "--node", str(NODE), "0x2003", "--type", "i16")
        check(rc == 0 and out == "-5", "signed SDO read")
        rc, out = hytask("canopen", *t, "sdo-write", "--node", str(NODE), "0x2001", "0", "123456", "--type", "u32")
        check(rc == 0 and node.sdo[0x2001].raw == 123456, "expedited SDO write lands in the peer")
        label = "a label longer than one segment"
        rc, out = hytask("canopen", *t, "sdo-write", "--node", str(NODE), "0x2002", "0", label, "--type", "str")
        check(rc == 0 and node.sdo[0x2002].raw == label, "segmented SDO write lands in the peer")
        rc, out = hytask("canopen", *t, "sdo-read", "--node", str(NODE), "0x2fff", "0")
        check(rc != 0 and f"node {NODE}" in out and "2FFF" in out and "does not exist" in out,
              "an SDO abort is a named error (node, object, abort text)")
        rc, out = hytask("canopen", "--iface", IFACE, "--timeout-ms", "300", "sdo-read", "--node", "9", "0x1000")
        check(rc != 0 and "node 9" in out and "time" in out.lower(), "a silent node is an SDO timeout naming it")

        for cmd, want in (("start", "OPERATIONAL"), ("stop", "STOPPED"), ("preop", "PRE-OPERATIONAL")):
            rc, out = hytask("canopen", *t, "nmt", cmd, "--node", str(NODE))
            wait_for(lambda: node.nmt.state == want, f"peer in {want}")
            check(rc == 0 and node.nmt.state == want, f"NMT {cmd} -> peer {want}")
        rc, out = hytask("canopen", *t, "nmt", "start")
        wait_for(lambda: node.nmt.state == "OPERATIONAL", "broadcast start")
        check(rc == 0, "NMT start to all nodes")

        rc, out = hytask("canopen", "--iface", IFACE, "--timeout-ms", "1500", "heartbeat",
                         "--nodes", str(NODE), "--for-ms", "3000")
        check(rc == 0 and f"node {NODE}: alive, operational" in out, "heartbeat consumer: the peer is alive")
        node.nmt.stop_heartbeat()
        time.sleep(0.2)
        rc, out = hytask("canopen", "--iface", IFACE, "--timeout-ms", "1000", "heartbeat",
                         "--nodes", str(NODE), "--for-ms", "5000")
        check(rc != 0 and f"node {NODE}: heartbeat lost" in out, "heartbeat consumer: a silent peer is lost, by name")
    finally:
        node.nmt.stop_heartbeat()
        net.disconnect()
    finish("test_canopen_tool")


if __name__ == "__main__":
    main()
