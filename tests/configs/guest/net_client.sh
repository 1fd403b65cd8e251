#!/bin/sh
# Scenario net_two_guests: the client guest (10.0.2.16) fetches from the server guest
# over eth0 (their frame ports joined by channels), retrying until it serves.
i=0
until wget -q -O /tmp/page http://10.0.2.15/; do
	i=$((i+1))
	[ $i -lt 30 ] || { echo "no answer"; exit 1; }
	sleep 1
done
cat /tmp/page
wget -q -O - "http://10.0.2.15/cgi-bin/hello?from=two"
echo "10.0.2.15 one" >> /etc/hosts
wget -q -O - http://one/index.html
i=0
while [ $i -lt 20 ]; do
	wget -q -O /dev/null http://10.0.2.15/ || echo "request $i failed"
	i=$((i+1))
done
echo "20 more requests"
ifconfig eth0 | grep -q "RX packets:[1-9]" && echo "eth0 received frames"
echo done
