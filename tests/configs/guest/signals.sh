# Scenario guest_signals: handlers, default actions, stops, EINTR and SIGPIPE in busybox's
# shell (trap, kill and wait are its builtins).
trap 'echo caught USR1' USR1
kill -USR1 $$
echo after trap
/bin/busybox sleep 0.1
echo slept
/bin/busybox sh -c 'kill -TERM $$; echo not reached'
echo "self-kill status $?"
/bin/busybox sh -c 'trap "echo child caught INT" INT; kill -INT $$; echo child goes on'
/bin/busybox sleep 10 &
pid=$!
kill $pid
wait $pid
echo "sleep killed status $?"
/bin/busybox sleep 10 &
pid=$!
kill -STOP $pid
kill -CONT $pid
kill -KILL $pid
wait $pid
echo "stopped then killed status $?"
/bin/busybox yes | /bin/busybox head -n 2
echo "pipeline status $?"
/bin/busybox sh -c 'trap "echo alarm rang" ALRM; /bin/busybox sleep 0.05; kill -ALRM $$; echo after alarm'
/bin/busybox sh -c 'trap "echo busy loop interrupted; exit 3" USR1; while :; do :; done' &
pid=$!
/bin/busybox sleep 0.1
kill -USR1 $pid
wait $pid
echo "busy status $?"
echo done
