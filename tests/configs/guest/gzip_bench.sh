#!/bin/sh
# Run by `cargo xtask bench --guest-smp` (xtask/src/guestsmpbench.rs) in a guest on one or
# two CPUs: 8 files gzipped by `xargs -P2` (two gzips at a time), ROUNDS times; each round
# prints `round <n> cs <centiseconds>` from /proc/uptime, then the files are gunzipped for
# the next. `gzip bench done` ends the run.
ROUNDS=5
# /proc/uptime's first field in centiseconds.
now() {
	read up _ < /proc/uptime
	echo "${up%.*}${up#*.}"
}
mkdir /tmp/z
for i in 1 2 3 4 5 6 7 8; do seq $i 3 300000 > /tmp/z/f$i; done
echo "files $(cat /tmp/z/f* | wc -c) bytes"
round=1
while [ $round -le $ROUNDS ]; do
	start=$(now)
	ls /tmp/z/f* | xargs -P2 -n1 gzip
	end=$(now)
	echo "round $round cs $((end - start))"
	gunzip /tmp/z/*.gz
	round=$((round + 1))
done
echo "gzip bench done"
