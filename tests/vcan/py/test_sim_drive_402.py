"""python-canopen's BaseNode402 as master against `hytask sim-drive` on vcan0: NMT and
heartbeat, SDO (expedited and segmented), PDO remap, the CiA 402 state machine to
Operation enabled, a Profile Position move, and the fault injection objects seen as EMCY,
a drive fault and a silent heartbeat. Interoperability: an independent master, not ours."""
import time

import canopen

from vcanlib import (HANG_GUARD, HYTASK, IFACE, RELAX, Proc, check, drive_od, finish, network,
                     relax_timeouts, wait_for)

NODE = 1


def heartbeat_state(node, want):
    """Waits (hang guard) until a heartbeat reports `want`; returns the last state."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < HANG_GUARD:
        s = node.nmt.wait_for_heartbeat(timeout=HANG_GUARD)
        if s == want:
            return s
    return s


def emcy_seen(node, code):
    """Waits (hang guard) for an EMCY with `code` in the consumer's log. (The EMCY follows
    the SDO answer at once, so it may be logged before a `wait()` would start.)"""
    wait_for(lambda: any(e.code == code for e in node.emcy.log), f"EMCY 0x{code:04X}")
    return True


def main():
    drive = Proc([HYTASK, "sim-drive", "--iface", IFACE, "--node", str(NODE), "--heartbeat-ms", "100"])
    net = None
    try:
        drive.wait_line("ready")
        net = network()
        node = canopen.BaseNode402(NODE, drive_od())
        net.add_node(node)
        relax_timeouts(node)

        # NMT and heartbeat.
        check(heartbeat_state(node, "PRE-OPERATIONAL") == "PRE-OPERATIONAL", "boot: pre-operational by heartbeat")
        node.nmt.state = "STOPPED"
        check(heartbeat_state(node, "STOPPED") == "STOPPED", "NMT stop seen in the heartbeat")
        node.nmt.state = "PRE-OPERATIONAL"
        check(heartbeat_state(node, "PRE-OPERATIONAL") == "PRE-OPERATIONAL", "NMT pre-operational")

        # SDO: expedited and segmented uploads, a forced segmented download.
        check(node.sdo[0x1000].raw == 0x00020192, "SDO 0x1000 device type = 0x00020192 (CiA 402 servo)")
        check(node.sdo[0x1018][2].raw == 0x48595431, "SDO 0x1018:2 product code")
        check(node.sdo[0x1018][4].raw == NODE, "SDO 0x1018:4 serial = node id")
        check(node.sdo[0x1008].raw == "hytask loopback CiA 402 drive", "segmented SDO upload of 0x1008")
        node.sdo.download(0x607A, 0, (1234).to_bytes(4, "little", signed=True), force_segment=True)
        check(node.sdo[0x607A].raw == 1234, "segmented SDO download of 0x607A")
        try:
            node.sdo.upload(0x1018, 9)
            check(False, "SDO read of 0x1018:9 aborts")
        except canopen.SdoAbortedError as e:
            check(e.code == 0x06090011, f"SDO read of 0x1018:9 aborts with 0x06090011 (got 0x{e.code:08X})")
        node.sdo[0x1017].raw = 50
        check(node.sdo[0x1017].raw == 50, "heartbeat time written over SDO")

        # PDO remap (disable, clear, map, enable: python-canopen's save()).
        node.tpdo.read()
        node.rpdo.read()
        node.tpdo[1].clear()
        node.tpdo[1].add_variable(0x6041)
        node.tpdo[1].add_variable(0x6061)
        node.tpdo[1].trans_type = 1
        node.tpdo[1].enabled = True
        node.tpdo[2].clear()
        node.tpdo[2].add_variable(0x6064)
        node.tpdo[2].add_variable(0x606C)
        node.tpdo[2].cob_id = 0x280 + NODE
        node.tpdo[2].trans_type = 1
        node.tpdo[2].enabled = True
        node.rpdo[1].clear()
        node.rpdo[1].add_variable(0x6040)
        node.rpdo[1].add_variable(0x607A)
        node.rpdo[1].trans_type = 1
        node.rpdo[1].enabled = True
        node.tpdo.save()
        node.rpdo.save()
        check(node.sdo[0x1A01][0].raw == 2 and node.sdo[0x1A01][1].raw == 0x60640020,
              "TPDO2 mapping stored: 0x6064 + 0x606C")
        node.setup_402_state_machine(read_pdos=True)
        check([v.index for v in node.tpdo[1].map] == [0x6041, 0x6061], "TPDO1 read back: statusword, mode display")
        check([v.index for v in node.rpdo[1].map] == [0x6040, 0x607A], "RPDO1 read back: controlword, target")
        try:
            node.sdo.download(0x1A00, 1, (0x60770010).to_bytes(4, 'little'))
            check(False, "changing the mapping of an enabled TPDO is refused")
        except canopen.SdoAbortedError as e:
            check(e.code == 0x08000022,
                  f"changing the mapping of an enabled TPDO is refused with 0x08000022 (got 0x{e.code:08X})")

        # Operational, SYNC-driven.
        node.nmt.state = "OPERATIONAL"
        check(heartbeat_state(node, "OPERATIONAL") == "OPERATIONAL", "NMT start: operational")
        node.rpdo[1]["Controlword"].raw = 0
        node.rpdo[1]["Target position"].raw = 0
        net.sync.start(0.01)
        node.rpdo[1].start(0.01)
        check(node.tpdo[2].wait_for_reception(HANG_GUARD) is not None, "TPDO2 arrives on SYNC")

        # CiA 402 state machine.
        node.state = "SWITCH ON DISABLED"
        node.state = "OPERATION ENABLED"
        check(node.state == "OPERATION ENABLED", f"402 state machine to OPERATION ENABLED (is {node.state})")

        # Profile Position move.
        node.op_mode = "PROFILED POSITION"
        check(node.op_mode == "PROFILED POSITION", "mode PP confirmed by 0x6061")
        pos0 = node.tpdo_values[0x6064]
        target = pos0 + 5000
        node.rpdo[1]["Target position"].raw = target
        node.tpdo[1].wait_for_reception(HANG_GUARD)
        node.tpdo[1].wait_for_reception(HANG_GUARD)
        node.controlword = 0x1F  # new set-point (bit 4 rising), enabled
        wait_for(lambda: node.tpdo_values[0x6064] == target and node.statusword & 0x0400,
                 "PP move to the target with target reached")
        check(node.tpdo_values[0x6064] == target, f"PP move reached {target}")
        check(node.statusword & 0x0400 != 0, "statusword target reached (bit 10)")
        node.controlword = 0x0F

        # Fault injection: a drive fault with its EMCY, then fault reset.
        node.emcy.reset()
        node.sdo[0x2000][1].raw = 0x7300
        check(emcy_seen(node, 0x7300), "injected drive fault arrives as EMCY 0x7300")
        wait_for(lambda: node.is_faulted(), "statusword fault bit")
        check(node.state == "FAULT", "402 state FAULT after the injected fault")
        node.reset_from_fault()
        check(node.state == "OPERATION ENABLED", f"fault reset back to OPERATION ENABLED (is {node.state})")
        # An EMCY without a fault.
        node.sdo[0x2000][3].raw = 0x5000
        check(emcy_seen(node, 0x5000), "injected EMCY 0x5000 arrives")
        check(node.state == "OPERATION ENABLED", "an EMCY alone does not fault the drive")
        # Heartbeat stop and resume.
        node.sdo[0x2000][2].raw = 1
        time.sleep(0.5 * RELAX / 10)
        try:
            node.nmt.wait_for_heartbeat(timeout=3.0)
            check(False, "heartbeat stops on injection")
        except canopen.nmt.NmtError:
            check(True, "heartbeat stops on injection")
        node.sdo[0x2000][2].raw = 0
        check(node.nmt.wait_for_heartbeat(timeout=HANG_GUARD) == "OPERATIONAL", "heartbeat resumes")
    finally:
        if net is not None:
            net.sync.stop()
            net.disconnect()
        rc = drive.stop()
    check(rc == 0, f"sim-drive exits 0 on SIGTERM (got {rc})")
    finish("test_sim_drive_402")


if __name__ == "__main__":
    main()
