#!/usr/bin/env python3
"""The SCADA side of `cargo xtask bench`'s PLC network benchmark: pymodbus 3.x (from PyPI,
in the venv target/pymodbus-venv) reads 10 holding registers N times in all at RATE
requests a second over C connections (each its own thread, RATE/C a second; one connection
cannot go faster than its round trip), as a SCADA poll does. Usage: modbus_bench.py PORT N
RATE C. Prints `roundtrip_us <t>` per request (the host's clock, request sent to answer
read) and exits non-zero when a request fails."""

import sys
import threading
import time

import pymodbus
from pymodbus.client import ModbusTcpClient

PORT, COUNT, RATE, CONNECTIONS = (
    int(sys.argv[1]),
    int(sys.argv[2]),
    float(sys.argv[3]),
    int(sys.argv[4]),
)
lock = threading.Lock()
failures = []


def unit_kw(unit):
    # pymodbus renamed `slave` to `device_id` in 3.10.
    major, minor = (int(x) for x in pymodbus.__version__.split(".")[:2])
    return {"device_id": unit} if (major, minor) >= (3, 10) else {"slave": unit}


def poll(count, offset):
    client = ModbusTcpClient("127.0.0.1", port=PORT, timeout=10)
    if not client.connect():
        failures.append(f"cannot connect to 127.0.0.1:{PORT}")
        return
    gap = CONNECTIONS / RATE
    next_at = time.monotonic() + offset
    for i in range(count):
        time.sleep(max(0.0, next_at - time.monotonic()))
        next_at += gap
        start = time.perf_counter_ns()
        reply = client.read_holding_registers(0, count=10, **unit_kw(1))
        took = time.perf_counter_ns() - start
        if reply.isError():
            failures.append(f"request {i}: {reply}")
            break
        with lock:
            print(f"roundtrip_us {took / 1000:.1f}", flush=True)
    client.close()


threads = [
    threading.Thread(target=poll, args=(COUNT // CONNECTIONS + (c < COUNT % CONNECTIONS), c / RATE))
    for c in range(CONNECTIONS)
]
for t in threads:
    t.start()
for t in threads:
    t.join()
if failures:
    sys.exit("; ".join(failures))
