#!/usr/bin/env python3
"""The SCADA side of `cargo xtask bench`'s PLC network benchmark: pymodbus 3.x (from PyPI,
in the venv target/pymodbus-venv) reads 10 holding registers N times, one request every
1/RATE s on one connection, as a SCADA poll does. Usage: modbus_bench.py PORT N RATE.
Prints `roundtrip_us <t>` per request (the host's clock, request sent to answer read) and
exits non-zero when a request fails."""

import sys
import time

import pymodbus
from pymodbus.client import ModbusTcpClient

PORT, COUNT, RATE = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])


def unit_kw(unit):
    # pymodbus renamed `slave` to `device_id` in 3.10.
    major, minor = (int(x) for x in pymodbus.__version__.split(".")[:2])
    return {"device_id": unit} if (major, minor) >= (3, 10) else {"slave": unit}


client = ModbusTcpClient("127.0.0.1", port=PORT, timeout=10)
if not client.connect():
    sys.exit(f"cannot connect to 127.0.0.1:{PORT}")
gap = 1.0 / RATE
next_at = time.monotonic()
for i in range(COUNT):
    start = time.perf_counter_ns()
    reply = client.read_holding_registers(0, count=10, **unit_kw(1))
    took = time.perf_counter_ns() - start
    if reply.isError():
        sys.exit(f"request {i}: {reply}")
    print(f"roundtrip_us {took / 1000:.1f}", flush=True)
    next_at += gap
    time.sleep(max(0.0, next_at - time.monotonic()))
client.close()
