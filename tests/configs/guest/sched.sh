# Scenario guest_sched: how the guest shares the CPU. The same work alone and beside a
# process spinning in user code: 2,000 system calls (dd copies 1,000 bytes one at a time, a
# read and a write each) and a loop of 20 short processes (a shell's fork, execve, exit and
# wait of /bin/true); then two CPU-bound counters started together beside the spinner
# share the CPU with it in turn; then a counter beside a pipe whose two ends keep the CPU
# busy between them, blocking every few calls, still gets its share. Every step logs a
# `sched:` line; the test reads their time stamps (virtual time).
count() {
    i=0
    while [ $i -lt 3000 ]; do i=$((i+1)); done
    echo "sched: counter $1 done"
}
echo "sched: counter alone"
count 0
echo "sched: calls alone"
dd if=/dev/zero of=/dev/null bs=1 count=1000 2>/dev/null
echo "sched: calls alone done"
i=0
while [ $i -lt 20 ]; do /bin/true; i=$((i+1)); done
echo "sched: processes alone done"

while :; do :; done &
hog=$!
echo "sched: calls beside a hog"
dd if=/dev/zero of=/dev/null bs=1 count=1000 2>/dev/null
echo "sched: calls beside a hog done"
i=0
while [ $i -lt 20 ]; do /bin/true; i=$((i+1)); done
echo "sched: processes beside a hog done"

echo "sched: counters"
count 1 &
first=$!
count 2 &
second=$!
wait $first $second
kill $hog
wait $hog
echo "sched: hog ended with $?"

yes | cat >/dev/null &
reader=$!
echo "sched: counter beside a busy pipe"
count 3
kill $reader
wait
echo "sched: done"
