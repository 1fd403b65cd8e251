#!/bin/sh
# Scenario net_guest_wget: fetch a file from the test's HTTP server on the host (QEMU's
# user network forwards 10.0.2.100:80 to it) with busybox wget, retrying while the host
# side is not yet there, and print its SHA-256 and size.
i=0
until wget -q -O /tmp/fetched http://10.0.2.100/payload; do
	i=$((i+1))
	[ $i -lt 20 ] || { echo "no answer"; exit 1; }
	sleep 2
done
sha256sum /tmp/fetched
wc -c < /tmp/fetched
echo done
