"""An independent Modbus server (pymodbus) for hytask's client tests.

Usage: pymodbus_server.py tcp PORT | rtu DEVICE
Serves unit 1 with known values: discrete inputs 0..3 = 1,0,1,1; input registers
0..3 = 0x1234, 0xFFFE, then 12.5 as f32 low word first (0x0000, 0x4148); holding register 5
= 0b1010. Prints "ready" when serving; over TCP "ready PORT" once listening, so PORT 0 (a port
the kernel picks, which no other test binary can take in between) is the tests' choice. On
stdin, "get co|hr ADDR" prints the value (to check what the client wrote).
"""
import asyncio
import sys
import threading

from pymodbus.datastore import (ModbusDeviceContext, ModbusSequentialDataBlock,
                                ModbusServerContext)
from pymodbus.server import ModbusTcpServer, StartSerialServer


def block(values):
    # pymodbus' device context maps protocol address a to block address a + 1.
    return ModbusSequentialDataBlock(0, [0] + values + [0] * 32)


device = ModbusDeviceContext(
    di=block([1, 0, 1, 1]),
    co=block([0] * 8),
    ir=block([0x1234, 0xFFFE, 0x0000, 0x4148]),
    hr=block([0, 0, 0, 0, 0, 0b1010, 0, 0]),
)
context = ModbusServerContext(devices={1: device}, single=False)


def commands():
    for line in sys.stdin:
        w = line.split()
        if len(w) == 3 and w[0] == "get":
            fc = 1 if w[1] == "co" else 3
            print(w[1], w[2], device.getValues(fc, int(w[2]), 1)[0], flush=True)


async def serve_tcp(port):
    server = ModbusTcpServer(context=context, address=("127.0.0.1", port))
    await server.serve_forever(background=True)
    print("ready", server.transport.sockets[0].getsockname()[1], flush=True)
    await server.serving


threading.Thread(target=commands, daemon=True).start()
if sys.argv[1] == "tcp":
    asyncio.run(serve_tcp(int(sys.argv[2])))
else:
    print("ready", flush=True)
    StartSerialServer(context=context, port=sys.argv[2], baudrate=19200, timeout=0.05)
