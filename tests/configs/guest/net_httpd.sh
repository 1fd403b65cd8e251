#!/bin/sh
# Scenario net_guest_httpd: busybox httpd on eth0 (10.0.2.15:80, reached from the host
# through QEMU's hostfwd and the NIC partition) serves a page and CGI scripts; the host's
# request to /cgi-bin/finish ends this script, and with it the run.
mkdir -p /tmp/www/cgi-bin
echo "<h1>served by the guest</h1>" > /tmp/www/index.html
printf '#!/bin/sh\necho "Content-Type: text/plain"\necho\necho "cgi in the guest says $QUERY_STRING"\n' > /tmp/www/cgi-bin/hello
printf '#!/bin/sh\ntouch /tmp/finished\necho "Content-Type: text/plain"\necho\necho finishing\n' > /tmp/www/cgi-bin/finish
chmod +x /tmp/www/cgi-bin/hello /tmp/www/cgi-bin/finish
httpd -p 80 -h /tmp/www || { echo "httpd did not start"; exit 1; }
echo "serving"
until [ -e /tmp/finished ]; do sleep 1; done
ifconfig eth0 | grep -q "RX packets:[1-9]" && echo "eth0 received frames"
echo "finished"
