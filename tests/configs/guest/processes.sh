# Scenario guest_processes: 200 short processes one after the other, ten at once, and an
# orphan that init (this shell) inherits and reaps, then 20 more beside a process spinning
# in user code (the guest's scheduling policy keeps them about as fast as alone).
i=0
while [ $i -lt 200 ]; do /bin/true; i=$((i+1)); done
echo "ran $i processes"
for n in 1 2 3 4 5 6 7 8 9 10; do /bin/busybox sleep 0.05 & done
wait
echo "ten in parallel reaped"
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
