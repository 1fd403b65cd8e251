#!/bin/sh
# The guest of scenario system_devices: the ARINC port devices /dev/arinc/<port> from a
# Linux program (linux-arinc, tests/linux/arinc.c) and from busybox one-liners. Each line
# of output is checked (tests/tests/system_ports.rs).
linux-arinc check
echo "arinc status $?"

# The devices, and the plant's level (a sampling port the plant writes every 10 ms).
echo "devices: $(ls /dev/arinc | tr '\n' ' ')"
echo "level: $(od -A n -t f8 -N 8 /dev/arinc/level)"
# A sampling message written with printf and read with dd (the loop back channel).
printf ping > /dev/arinc/sample-out
echo "sampling: $(dd if=/dev/arinc/sample-in bs=16 count=1 2>/dev/null)"
echo "sampling again: $(dd if=/dev/arinc/sample-in bs=16 count=1 2>/dev/null)"
# Queuing messages: two written, two read in order, bytes through od.
printf one > /dev/arinc/queue-out
printf two > /dev/arinc/queue-out
echo "queuing: $(dd if=/dev/arinc/queue-in bs=32 count=2 2>/dev/null)"
printf '\001\002\377' > /dev/arinc/queue-out
echo "queuing bytes: $(dd if=/dev/arinc/queue-in bs=32 count=1 2>/dev/null | od -A n -t u1)"
# A read that waits for a message another process writes a second later.
(sleep 1; printf late > /dev/arinc/queue-out) &
echo "waited for: $(dd if=/dev/arinc/queue-in bs=32 count=1 2>/dev/null)"
wait
# Message sizes: a read buffer smaller than the port, a write larger than it.
dd if=/dev/arinc/sample-in of=/dev/null bs=4 count=1 2>&1 | head -n 1
dd if=/dev/zero of=/dev/arinc/queue-out bs=33 count=1 2>&1 | head -n 1
# The PLC's online service, both ways: a READ of `valve` (op 2, seq 7), its answer's head
# (op, seq, status OK, type LREAL).
printf '\002\007valve' > /dev/arinc/plc-request
echo "plc answer: $(dd if=/dev/arinc/plc-response bs=256 count=1 2>/dev/null | od -A n -t u1 -N 4)"
echo done
