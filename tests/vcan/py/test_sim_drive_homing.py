"""python-canopen's BaseNode402.homing() as master against `hytask sim-drive`: CiA 402
homing mode (0x6060 = 6, confirmed by 0x6061) with method 19 on the drive's simulated home
switch, the search and zero speeds 0x6099, acceleration 0x609A and home offset 0x607C;
statusword bits 12/10 end it. Then method 35 (current position), and an unsupported
method ends in a homing error (bit 13). State machine and statusword go by SDO."""
import logging

import canopen

from vcanlib import HYTASK, IFACE, Proc, check, drive_od, finish, network, relax_timeouts

NODE = 4


def main():
    # Without PDOs python-canopen warns on every statusword poll that it falls back to SDO.
    logging.getLogger("canopen.profiles.p402").setLevel(logging.ERROR)
    drive = Proc([HYTASK, "sim-drive", "--iface", IFACE, "--node", str(NODE)])
    net = None
    try:
        drive.wait_line("ready")
        net = network()
        node = canopen.BaseNode402(NODE, drive_od())
        net.add_node(node)
        relax_timeouts(node)
        node.TIMEOUT_HOMING_DEFAULT = 120
        node.sdo[0x2002][1].raw = 4000
        node.sdo[0x6099][1].raw = 40000
        node.sdo[0x6099][2].raw = 2000
        node.sdo[0x609A].raw = 2000000
        node.sdo[0x607C].raw = 250
        node.sdo[0x6098].raw = 19
        node.state = "SWITCH ON DISABLED"
        ok = node.homing()
        check(ok, "method 19 (home switch) homed")
        check(node.sdo[0x6061].raw == 6, "0x6061 confirms homing mode")
        sw = node.sdo[0x6041].raw
        check(sw & 0x1000 != 0 and sw & 0x2000 == 0, f"statusword 0x{sw:04X}: homing attained, no error")
        pos = node.sdo[0x6064].raw
        check(abs(pos - 250) <= 2, f"position at the home offset (got {pos})")
        node.sdo[0x607C].raw = -40
        node.sdo[0x6098].raw = 35
        node.controlword = 0x0F  # bit 4 low: the next start is a rising edge
        check(node.homing(), "method 35 (current position) homed")
        check(node.sdo[0x6064].raw == -40, "position = home offset")
        node.sdo[0x6098].raw = 1
        node.controlword = 0x0F
        check(not node.homing(timeout=30), "method 1 is refused")
        check(node.sdo[0x6041].raw & 0x2000 != 0, "homing error (bit 13)")
    finally:
        if net is not None:
            net.disconnect()
        drive.stop()
    finish("test_sim_drive_homing")


if __name__ == "__main__":
    main()
