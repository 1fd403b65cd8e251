#!/usr/bin/env python3
"""The host's Modbus/TCP client of scenario net_modbus: pymodbus 3.x (from PyPI, in the
venv `.ci/run` makes), not ours. Usage: modbus_client.py PORT [stopped]. Reads the tank's
level, writes the setpoint marker and provokes each exception the PLC can give while it
runs; with `stopped` (every task of the PLC stopped over its online service), checks that a
write gets exception 4 and a read still its answer. Prints one `check <name> ok|FAIL
<detail>` line per check and `level <m>` lines, and exits 0 when every check passed."""

import struct
import sys
import time

import pymodbus
from pymodbus.client import ModbusTcpClient

PORT = int(sys.argv[1])
STOPPED = sys.argv[2:] == ["stopped"]
UNIT = 1
MARKERS = 0x3000  # holding register of %MW0 (the setpoint in mm)
failed = []


def unit_kw(unit):
    # pymodbus renamed `slave` to `device_id` in 3.10.
    major, minor = (int(x) for x in pymodbus.__version__.split(".")[:2])
    return {"device_id": unit} if (major, minor) >= (3, 10) else {"slave": unit}


def check(name, ok, detail=""):
    print(f"check {name} {'ok' if ok else 'FAIL'} {detail}", flush=True)
    if not ok:
        failed.append(name)


def exception_of(rr):
    return getattr(rr, "exception_code", None) if rr.isError() else None


def level(client):
    rr = client.read_input_registers(0, count=4, **unit_kw(UNIT))
    if rr.isError():
        return None
    return struct.unpack("<d", struct.pack("<4H", *rr.registers))[0]


client = ModbusTcpClient("127.0.0.1", port=PORT, timeout=5, retries=3)
deadline = time.time() + 120
while not client.connect() or level(client) is None:
    if time.time() > deadline:
        check("connect", False, "no answer for 120 s")
        sys.exit(1)
    client.close()
    time.sleep(1)
print(f"pymodbus {pymodbus.__version__}", flush=True)

if STOPPED:
    rr = client.write_register(MARKERS, 600, **unit_kw(UNIT))
    check("exception_4_stopped", exception_of(rr) == 4, f"{rr}")
    rr = client.write_coil(MARKERS * 1 + 8 * 40, True, **unit_kw(UNIT))
    check("exception_4_stopped_coil", exception_of(rr) == 4, f"{rr}")
    rr = client.read_holding_registers(MARKERS, count=1, **unit_kw(UNIT))
    check("read_while_stopped", not rr.isError(), f"{getattr(rr, 'registers', rr)}")
    client.close()
    sys.exit(1 if failed else 0)

first = level(client)
check("read_input_registers", first is not None and 0.0 < first < 2.0, f"level={first}")
rr = client.read_discrete_inputs(64, count=1, **unit_kw(UNIT))
check("read_discrete_inputs", not rr.isError() and rr.bits[0], "%IX8.0 level_ok")
rr = client.read_coils(128, count=1, **unit_kw(UNIT))
check("read_coils", not rr.isError(), f"%QX16.0 alarm={not rr.isError() and rr.bits[0]}")
rr = client.read_holding_registers(MARKERS, count=1, **unit_kw(UNIT))
check("read_holding_registers", not rr.isError() and rr.registers == [1000], f"{getattr(rr, 'registers', rr)}")
rr = client.write_register(MARKERS + 1, 7, **unit_kw(UNIT))
check("write_register", not rr.isError())
rr = client.write_registers(MARKERS + 2, [1, 2, 3], **unit_kw(UNIT))
check("write_registers", not rr.isError())
rr = client.write_coil(MARKERS * 1 + 8 * 40, True, **unit_kw(UNIT))
check("write_coil", not rr.isError(), "%MX40.0")
rr = client.write_coils(MARKERS + 8 * 41, [True, False, True], **unit_kw(UNIT))
check("write_coils", not rr.isError(), "%MX41.0..2")
time.sleep(0.2)
rr = client.read_holding_registers(MARKERS + 1, count=4, **unit_kw(UNIT))
check("read_back", not rr.isError() and rr.registers[:4] == [7, 1, 2, 3], f"{getattr(rr, 'registers', rr)}")
rr = client.read_coils(MARKERS + 8 * 40, count=11, **unit_kw(UNIT))
check("read_back_coils", not rr.isError() and rr.bits[0] and rr.bits[8:11] == [True, False, True], f"{getattr(rr, 'bits', rr)}")

# Exceptions: 1 an unsupported function, 2 outside the image and a read-only area,
# 3 a quantity out of range, 0x0A another unit id. (4, a write while the PLC is stopped:
# with `stopped`, above.)
unsupported = getattr(client, "read_exception_status", None) or getattr(client, "report_device_id")
rr = unsupported(**unit_kw(UNIT))
check("exception_1", exception_of(rr) == 1, f"{rr}")
rr = client.read_holding_registers(0x2FFF, count=2, **unit_kw(UNIT))
check("exception_2_unmapped", exception_of(rr) == 2, f"{rr}")
rr = client.write_register(0, 1, **unit_kw(UNIT))
check("exception_2_read_only", exception_of(rr) == 2, f"{rr}")
# pymodbus checks quantities before it sends: its own request class, with that check
# left out, sends 126 registers (at most 125 fit a response).
from pymodbus.pdu.register_message import ReadHoldingRegistersRequest


class UncheckedRead(ReadHoldingRegistersRequest):
    def verifyCount(self, max_count):
        pass


try:
    rr = client.execute(False, UncheckedRead(address=MARKERS, count=126, dev_id=UNIT))
    check("exception_3", exception_of(rr) == 3, f"{rr}")
except Exception as e:
    check("exception_3", False, f"pymodbus could not send the request: {e!r}")
rr = client.read_input_registers(0, count=4, **unit_kw(7))
check("exception_10", exception_of(rr) == 10, f"{rr}")

# The setpoint: 1.000 m -> 0.600 m; the level follows.
rr = client.write_register(MARKERS, 600, **unit_kw(UNIT))
check("write_setpoint", not rr.isError())
deadline = time.time() + 60
now = level(client)
while now is not None and now > 0.7 and time.time() < deadline:
    print(f"level {now:.3f}", flush=True)
    time.sleep(1)
    now = level(client)
check("level_follows", now is not None and now <= 0.7, f"level={now}")
client.close()
sys.exit(1 if failed else 0)
