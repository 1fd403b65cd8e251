#!/bin/sh
# Scenario iec61499_fbctl: fbctl over TCP to the IEC 61499 device at 10.0.2.15:61499,
# retrying until it answers (both boot at once), then a read, a query, a write its
# access does not allow, and a port nobody listens on; each command's exit status.
D=10.0.2.15:61499
i=0
until fbctl --tcp $D send STEADY '<Request ID="1" Action="READ"><Connection Source="COUNT.CV" Destination=""/></Request>'; do
	i=$((i+1))
	[ $i -lt 30 ] || { echo "no answer"; exit 1; }
	sleep 1
done
echo "read status $?"
fbctl --tcp $D send STEADY '<Request ID="2" Action="QUERY"><FB Name="*" Type="*"/></Request>'
echo "query status $?"
fbctl --tcp $D send '' '<Request ID="3" Action="CREATE"><FB Name="X" Type="EMB_RES"/></Request>'
echo "create status $?"
fbctl --tcp 10.0.2.15:61498 send STEADY '<Request ID="4" Action="QUERY"><FB Name="*" Type="*"/></Request>'
echo "closed port status $?"
