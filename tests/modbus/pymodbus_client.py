"""An independent Modbus client (pymodbus) against `hytask modbus-sim`.

Usage: pymodbus_client.py tcp HOST PORT | rtu DEVICE
Talks to unit 1 of the simulator serving tests/modbus/map.toml, prints one JSON object with
what it read, wrote and the exceptions it got.
"""
import json
import sys

from pymodbus.client import ModbusSerialClient, ModbusTcpClient

if sys.argv[1] == "tcp":
    client = ModbusTcpClient(sys.argv[2], port=int(sys.argv[3]), timeout=2)
else:
    client = ModbusSerialClient(port=sys.argv[2], baudrate=19200, timeout=2)
assert client.connect(), "connect failed"
out = {}
r = client.read_discrete_inputs(0, count=3, device_id=1)
out["di"] = [bool(b) for b in r.bits[:3]]
r = client.read_input_registers(0, count=4, device_id=1)
out["ir"] = list(r.registers)
client.write_coil(1, True, device_id=1)
client.write_registers(2, [0x4148, 0x0000], device_id=1)
r = client.read_coils(0, count=2, device_id=1)
out["co"] = [bool(b) for b in r.bits[:2]]
r = client.read_holding_registers(2, count=2, device_id=1)
out["hr"] = list(r.registers)
r = client.read_holding_registers(1000, count=1, device_id=1)
out["exception"] = r.exception_code if r.isError() else None
client.close()
print(json.dumps(out), flush=True)
