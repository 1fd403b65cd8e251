#!/bin/sh
# Scenario net_sockets (tests/configs/net_sockets.toml): unmodified busybox networking
# applets on the guest's loopback, and its eth0 as ifconfig and route show it. Every
# stdout line is checked in order (tests/tests/net_sockets.rs).
# nc: a server and a client on 127.0.0.1.
nc -l -p 5000 > /tmp/received &
server=$!
sleep 1
echo "hello over tcp" | nc 127.0.0.1 5000
wait $server
echo "nc server exit $?"
cat /tmp/received
# nc the other way: the server sends, the client receives.
echo "from the server" | nc -l -p 5001 &
server=$!
sleep 1
nc 127.0.0.1 5001 < /dev/null
wait $server
# httpd serving a directory and a CGI script.
mkdir -p /tmp/www/cgi-bin
echo "<h1>static page</h1>" > /tmp/www/index.html
printf '#!/bin/sh\necho "Content-Type: text/plain"\necho\necho "cgi says $QUERY_STRING"\n' > /tmp/www/cgi-bin/hello
chmod +x /tmp/www/cgi-bin/hello
httpd -f -p 127.0.0.1:8080 -h /tmp/www &
httpd=$!
sleep 1
wget -q -O - http://127.0.0.1:8080/
wget -q -O - "http://127.0.0.1:8080/cgi-bin/hello?x=42"
wget -q -O - http://localhost:8080/index.html
wget -q -O /tmp/missing http://127.0.0.1:8080/missing.html
echo "wget of a missing page $?"
kill $httpd
wait $httpd
nc 127.0.0.1 8080 </dev/null
echo "nc to a closed port $?"
# A connection towards the gateway: eth0 asks for its MAC (ARP) through its tx port,
# which the configuration loops back to its rx port; nobody answers, nc gives up.
nc -w 1 10.0.2.2 9 </dev/null &
sleep 1
ifconfig lo | grep -o "inet addr:[0-9.]*  Mask:[0-9.]*"
ifconfig lo | grep -o "UP LOOPBACK RUNNING  MTU:[0-9]*"
ifconfig eth0 | grep -o "HWaddr [0-9A-F:]*"
ifconfig eth0 | grep -o "inet addr:[0-9.]*  Bcast:[0-9.]*  Mask:[0-9.]*"
ifconfig eth0 | grep -o "UP BROADCAST RUNNING MULTICAST  MTU:[0-9]*"
ifconfig eth0 | grep -q "RX packets:[1-9]" && echo "eth0 received frames"
ifconfig eth0 | grep -q "TX packets:[1-9]" && echo "eth0 sent frames"
ifconfig | grep -o "^[a-z0-9]*"
route -n
grep -c . /proc/net/dev
echo done
