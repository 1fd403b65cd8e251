#!/bin/sh
# The hostile guest of scenario system_hostile_guest: after 3 s of an idle guest (the
# PLC's lateness then is the baseline), one attack after the other: a port flood, then a
# CPU hog through all the others (memory hogs, a pipe flood, a thread bomb), then a crash
# of init in the middle of a fork bomb; every step logs a `hostile:` line. A new Linux process, and one
# that waits (the floods' and the fork bomb's), runs at the highest priority the guest
# gives its processes (its scheduling policy, partitions/guest/src/sched.rs): the hog
# starts there, at the guest's maximum, and returns there for a slice whenever it has
# waited its turn too long. What it starts is bounded by the guest's memory, its file
# system and its process table.
echo "hostile: boot: a fresh shell, pid $$, $(echo runs commands)"
sleep 3
echo "hostile: idle phase over"

# A port flood: every port call is a request to syssw. Two programs write requests to
# the PLC's online service as fast as they can without waiting (valid, forbidden and
# garbage ones; the queue is mostly full) and drain the answers, for 2 s; in the second
# second a shell loop writes READ requests that wait for room, a dd reads answers that
# wait for them (woken first, these two take most of the room and of the answers: the
# first second is the flooders' own), another reads the plant's level as fast as it can.
linux-arinc flood /dev/arinc/plc-request /dev/arinc/plc-response 2 &
flooders=$!
linux-arinc flood /dev/arinc/plc-request /dev/arinc/plc-response 2 &
flooders="$flooders $!"
sleep 1
(while :; do printf '\002\001level' > /dev/arinc/plc-request; done) &
waiters=$!
dd if=/dev/arinc/plc-response of=/dev/null bs=256 2>/dev/null &
waiters="$waiters $!"
dd if=/dev/arinc/level of=/dev/null bs=8 2>/dev/null &
waiters="$waiters $!"
wait $flooders
kill $waiters
echo "hostile: port flood done"

# A CPU hog, alone for 4 s, then beside everything that follows (the guest's scheduling
# policy keeps the shell and the other attacks as quick as without it).
while :; do :; done &
echo "hostile: cpu hog started"
sleep 4

# Memory hogs: a buffer larger than the guest's memory, a string doubled until the
# memory is gone (stopped after 1 s), a file larger than the file system.
dd if=/dev/zero of=/dev/null bs=200M count=1 2>/dev/null
echo "hostile: dd of a 200 MiB block ended with status $?"
awk 'BEGIN { s = "0123456789abcdef"; while (1) s = s s }' 2>/dev/null &
hog=$!
sleep 1
kill -9 $hog 2>/dev/null
wait $hog
echo "hostile: memory hog ended with status $?"
dd if=/dev/zero of=/tmp/fill bs=1M count=64 2>/dev/null
echo "hostile: 64 MiB into the file system, dd ended with status $?"
rm /tmp/fill

# A pipe flood: writers as fast as they can, each into a reader, for 2 s.
readers=
for i in 1 2 3; do
    yes flood | cat >/dev/null &
    readers="$readers $!"
done
sleep 2
kill $readers
echo "hostile: pipe flood done"

# A thread bomb: one process creates threads until the guest refuses one (its process
# table or the partition's kernel thread quota is full), then ends with all of them.
linux-probe threads
echo "hostile: thread bomb done"

# A fork bomb: every copy starts two more until the guest's process table is full, then
# its forks fail (EAGAIN) while the copies that ended make room for new ones; a copy whose
# fork failed ends, so it burns out after about a second. Counting the processes needs no
# fork: a glob. Init crashes while it runs.
bomb() { bomb | bomb & }
bomb
sleep 0.5
set -- /proc/[0-9]*
echo "hostile: fork bomb running: $# processes"

echo "hostile: crash"
exec /bin/linux-probe segv
