# Scenario guest_processes: 200 short processes one after the other, forty at once, and an
# orphan that init (this shell) inherits and reaps, then 20 more beside a process spinning
# in user code (the guest's scheduling policy keeps them about as fast as alone).
i=0
while [ $i -lt 200 ]; do /bin/true; i=$((i+1)); done
echo "ran $i processes"
n=0
while [ $n -lt 40 ]; do /bin/busybox sleep 2 & n=$((n+1)); done
[ "$(/bin/busybox ls /proc | /bin/busybox grep -c '^[0-9]')" -gt 40 ] && echo "more than forty at once"
wait
echo "forty in parallel reaped"
/bin/busybox sh -c '/bin/busybox sleep 0.1 & echo orphan started'
echo "its parent is gone"
/bin/busybox sleep 0.3
/bin/true
/bin/busybox sh -c 'while :; do :; done' &
hog=$!
i=0
while [ $i -lt 20 ]; do /bin/true; i=$((i+1)); done
echo "ran $i processes beside a busy one"
kill $hog
wait $hog
echo "the busy one ended with $?"
echo done
