#!/bin/sh
# Scenario net_two_guests: the server guest (10.0.2.15) serves a page and a CGI script
# with busybox httpd on eth0 until the run ends.
mkdir -p /tmp/www/cgi-bin
echo "<h1>served by guest one</h1>" > /tmp/www/index.html
printf '#!/bin/sh\necho "Content-Type: text/plain"\necho\necho "cgi on guest one says $QUERY_STRING"\n' > /tmp/www/cgi-bin/hello
chmod +x /tmp/www/cgi-bin/hello
echo "serving"
exec httpd -f -p 80 -h /tmp/www
