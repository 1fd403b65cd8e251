#!/bin/sh
# Run by scenario guest_smp in a guest bound to CPUs 0 and 1: what a Linux user checks on
# a machine of two CPUs. Each line is compared with the scenario's expectation.
echo "nproc $(nproc)"
echo "cpuinfo $(grep -c '^processor' /proc/cpuinfo)"
echo "mask$(taskset -p $$ | cut -d: -f2)"
# taskset pins a program; field 39 of /proc/self/stat is the CPU it runs on.
for cpu in 0 1; do
	echo "pinned $cpu $(taskset -c $cpu cut -d' ' -f39 /proc/self/stat)"
done
taskset -c 5 true 2> /dev/null
echo "no CPU 5: $?"
# Two CPU-bound processes run on different CPUs.
spin() {
	i=0
	while [ $i -lt 20000 ]; do i=$((i + 1)); done
}
spin &
a=$!
spin &
b=$!
ca=$(cut -d' ' -f39 /proc/$a/stat)
cb=$(cut -d' ' -f39 /proc/$b/stat)
wait
if [ "$ca" != "$cb" ]; then echo "spread"; else echo "both on CPU $ca"; fi
# xargs -P2 gzip of 8 files: each comes back intact.
mkdir /tmp/z
for i in 1 2 3 4 5 6 7 8; do seq $i 3 60000 > /tmp/z/f$i; done
md5sum /tmp/z/f* > /tmp/sums
ls /tmp/z/f* | xargs -P2 -n1 gzip
echo "gzipped $(ls /tmp/z | grep -c '\.gz$')"
gunzip /tmp/z/*.gz
echo "intact $(md5sum -c /tmp/sums | grep -c ': OK$')"
exit 7
