#!/bin/sh
# The network benchmark of `cargo xtask bench --net` (xtask/src/netbench.rs), the same
# script in the guest partition of tests/configs/bench_net.toml and on Debian's stock
# kernel in the same QEMU: busybox httpd serves a 1 KiB page on port 80, linux-netserve
# (tests/linux/netserve.c) the TCP and UDP measurements on port 5001; the host's last
# request ends linux-netserve and so this script and the run.
mkdir -p /tmp/www
line="0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcde"
i=0
: > /tmp/www/page.html
while [ $i -lt 16 ]; do echo "$line" >> /tmp/www/page.html; i=$((i + 1)); done
httpd -p 80 -h /tmp/www || { echo "httpd did not start"; exit 1; }
/bin/linux-netserve 5001
