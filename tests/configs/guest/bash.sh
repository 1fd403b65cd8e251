#!/bin/bash
# Run by Debian's bash-static in the guest (scenario guest_bash) and on the host: each line
# it prints must be the same in both.
set -u

greet() { local who=$1; echo "hello, $who (${#who} letters)"; }
greet guest

# Indexed and associative arrays.
primes=(2 3 5 7 11)
primes+=(13)
echo "primes: ${primes[*]} count=${#primes[@]} third=${primes[2]} last=${primes[-1]}"
declare -A level=([tank]=42 [valve]=open [alarm]=off)
for key in $(printf '%s\n' "${!level[@]}" | sort); do echo "level[$key]=${level[$key]}"; done

# Arithmetic.
sum=0
for ((i = 1; i <= 100; i++)); do ((sum += i)); done
echo "sum 1..100 = $sum, 2**20 = $((2 ** 20)), 17 % 5 = $((17 % 5))"

# Here-documents and read.
while IFS=: read -r name value; do
    echo "read name=$name value=$value"
done <<END
setpoint:50
band:5
END
cat <<'RAW'
no $expansion here
RAW

# Regular expressions.
for word in PLC-42 guest 61499; do
    if [[ $word =~ ^([A-Z]+)-([0-9]+)$ ]]; then
        echo "$word: letters ${BASH_REMATCH[1]} number ${BASH_REMATCH[2]}"
    elif [[ $word =~ ^[0-9]+$ ]]; then
        echo "$word: a number"
    else
        echo "$word: a word"
    fi
done

# String operations.
path=/usr/local/bin/plcctl
echo "base=${path##*/} dir=${path%/*} upper=${path^^} replaced=${path//l/L}"

# Subshells and command substitution.
outer=kept
(outer=changed; echo "in the subshell: $outer")
echo "after the subshell: $outer"
nested=$(echo "one $(echo "two $(echo three)")")
echo "nested: $nested"

# Pipelines and their status.
echo "sorted: $(echo -e "c\nb\na" | sort | tr '\n' ' ')"
set +e
false | true
echo "pipeline status ${PIPESTATUS[*]}"
set -o pipefail
false | true
echo "with pipefail: $?"
set +o pipefail

# Case, brace expansion, defaults, printf -v, mapfile, a descriptor of our own and process
# substitution.
for state in running stopped faulted; do
    case $state in
        run*) echo "$state: the scan runs" ;;
        stopped | halted) echo "$state: outputs held" ;;
        *) echo "$state: outputs safe" ;;
    esac
done
echo "braces:" {1..5} {a,b}-x
unset missing
echo "default: ${missing:-none} length of PATH > 0: $(( ${#PATH} > 0 ))"
printf -v padded '%05d|%-6s|%x' 42 ok 255
echo "printf -v: $padded"
mapfile -t lines < <(printf 'first\nsecond\nthird\n')
echo "mapfile: ${#lines[@]} lines, last ${lines[2]}"
exec 3>/tmp/fd3.txt
echo "through descriptor 3" >&3
exec 3>&-
echo "read back: $(cat /tmp/fd3.txt)"
rm /tmp/fd3.txt
while read -r n; do total=$((${total:-0} + n)); done < <(seq 1 10)
echo "total from a process substitution: $total"

# Traps.
trap 'echo "trap: USR1 caught"' USR1
kill -USR1 $$
inner() { trap 'echo "trap: leaving the function"' RETURN; echo "inside"; }
inner
cleanup() { echo "trap: EXIT runs last"; }
trap cleanup EXIT

# Processes.
sleep 0 &
wait $!
echo "background job ended with $?"
echo "done"
