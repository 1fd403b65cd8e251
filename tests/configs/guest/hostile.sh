#!/bin/sh
# The hostile guest of scenario plc_guest_hostile: one attack after the other with a CPU
# hog through all of them, then a crash of init in the middle of a fork bomb; every step
# logs a `hostile:` line. Every Linux process runs at the same priority, the highest the
# guest gives its processes, so the hog is at the guest's maximum. What it starts is
# bounded by the guest's memory, its file system and its process table.
echo "hostile: boot: a fresh shell, pid $$, $(echo runs commands)"

while :; do :; done &
echo "hostile: cpu hog started"

# Memory hogs: a buffer larger than the guest's memory, a string doubled until the
# memory is gone (stopped after 2 s), a file larger than the file system.
dd if=/dev/zero of=/dev/null bs=200M count=1 2>/dev/null
echo "hostile: dd of a 200 MiB block ended with status $?"
awk 'BEGIN { s = "0123456789abcdef"; while (1) s = s s }' 2>/dev/null &
hog=$!
sleep 2
kill -9 $hog 2>/dev/null
wait $hog
echo "hostile: memory hog ended with status $?"
dd if=/dev/zero of=/tmp/fill bs=64k count=1024 2>/dev/null
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

# A fork bomb: every copy starts two more until the guest's process table is full, then
# its forks fail (EAGAIN) while the copies that ended make room for new ones. Counting
# the processes needs no fork: a glob. Init crashes while it runs.
bomb() { bomb | bomb & }
bomb
sleep 1
set -- /proc/[0-9]*
echo "hostile: fork bomb running: $# processes"

echo "hostile: crash"
exec /bin/linux-probe segv
