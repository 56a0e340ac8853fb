"""SDO block transfer on vcan0, both ways, against independent peers:

* python-canopen's client (`sdo.open(..., block_transfer=True)`) reads and writes the
  loopback drive's domain object 0x2001 by block upload and block download (CRC on);
* hytask's master (`hytask canopen sdo-read/sdo-write`) moves the same object by block
  transfer with the loopback drive (the requests seen on the bus are block requests);
* against python-canopen's LocalNode, which has no block server (2.4.1: a block upload
  is answered as a normal upload, a block download is aborted with 0x05040001), the
  master's block attempts fall back to the normal protocol and the values still arrive.
"""
import canopen
from canopen import objectdictionary as odm

from vcanlib import (IFACE, Proc, SdoWatch, check, domain_default, drive_od, finish, hytask,
                     network, relax_timeouts, var, HYTASK)

DRIVE = 3
PEER = 6


def with_drive(net):
    drive = Proc([HYTASK, "sim-drive", "--iface", IFACE, "--node", str(DRIVE)])
    try:
        drive.wait_line("ready")
        node = canopen.RemoteNode(DRIVE, drive_od())
        net.add_node(node)
        relax_timeouts(node)
        watch = SdoWatch(net, DRIVE)

        with node.sdo.open(0x2001, 0, "rb", block_transfer=True) as f:
            got = f.read()
        check(got == domain_default(), f"python-canopen block upload of 0x2001: {len(got)} bytes, CRC checked")
        check(0xC6 in watch.take()[1], "the drive answered a block upload (response 0xC6: CRC, size)")

        value = bytes((i * 13 + 1) % 256 for i in range(2000))
        with node.sdo.open(0x2001, 0, "wb", size=len(value), block_transfer=True) as f:
            f.write(value)
        check(watch.take()[1][:1] == [0xA4], "the drive answered a block download (response 0xA4: CRC)")
        check(node.sdo.upload(0x2001, 0) == value, "block download of 2000 bytes stored (read back segmented)")

        t = ["--iface", IFACE, "--timeout-ms", "5000"]
        rc, out = hytask("canopen", *t, "sdo-read", "--node", str(DRIVE), "0x2001", "--type", "hex")
        check(rc == 0 and bytes.fromhex(out) == value, "hytask master block upload of 2000 bytes")
        # the client's end-of-upload confirmation (0xA1) is the last frame
        req, resp = watch.take(until=lambda req, _resp: 0xA1 in req)
        check(0xA4 in req and 0xA3 in req and 0x60 not in req, "hytask's upload was a block upload")
        text = "block download from hytask's master: " + "x" * 80
        rc, out = hytask("canopen", *t, "sdo-write", "--node", str(DRIVE), "0x2001", "0", text, "--type", "str")
        # the drive's end-of-download response (0xA1) is the last frame
        req, resp = watch.take(until=lambda _req, resp: 0xA1 in resp)
        check(rc == 0 and 0xC6 in req and 0xA1 in resp, "hytask master block download (request 0xC6: CRC, size)")
        check(node.sdo.upload(0x2001, 0) == text.encode(), "the drive stored the block download")
    finally:
        drive.stop()


def peer_od():
    od = odm.ObjectDictionary()
    od.add_object(var("Device type", 0x1000, 0, odm.UNSIGNED32, "ro", default=0x191))
    od.add_object(var("Producer heartbeat time", 0x1017, 0, odm.UNSIGNED16, "rw", default=0))
    od.add_object(var("Label", 0x2002, 0, odm.VISIBLE_STRING, "rw", default=""))
    return od


def with_local_node(net):
    node = canopen.LocalNode(PEER, peer_od())
    net.add_node(node)
    node.nmt.state = "PRE-OPERATIONAL"
    watch = SdoWatch(net, PEER)
    t = ["--iface", IFACE, "--timeout-ms", "5000"]
    label = "a label long enough for a block transfer, " * 2
    rc, out = hytask("canopen", *t, "sdo-write", "--node", str(PEER), "0x2002", "0", label, "--type", "str")
    req, _ = watch.take()
    check(0xC6 in req and 0x21 in req, "block download tried, then segmented after abort 0x05040001")
    check(rc == 0 and node.sdo[0x2002].raw == label, "the LocalNode got the value segmented")
    rc, out = hytask("canopen", *t, "sdo-read", "--node", str(PEER), "0x2002", "--type", "str")
    req, _ = watch.take()
    check(0xA4 in req and 0x60 in req, "block upload tried, answered as a normal upload")
    check(rc == 0 and out == label.strip(), "the master read the LocalNode's value")


def main():
    net = network()
    try:
        with_drive(net)
        with_local_node(net)
    finally:
        net.disconnect()
    finish("test_sdo_block")


if __name__ == "__main__":
    main()
