#!/bin/sh
# The guest_busybox scenario's shell session (tests/tests/guest_busybox.rs expects its
# output line by line): the writable file system, /proc, pipelines, redirections, command
# substitution, loops, tests, text tools, tar and gzip, and exit codes.
cd /tmp || exit 1
pwd
printf 'banana\napple\ncherry\n' > fruits
echo date >> fruits
sort -r fruits | head -n 1
wc -l < fruits
grep -n an fruits
sed -e 's/a/A/g' fruits | head -n 2
awk '{ n += length($0) } END { print "chars", n }' fruits
count=$(grep -c e fruits)
echo "count $count"
for word in one two; do echo "for $word"; done
i=0
while [ $i -lt 3 ]; do i=$((i + 1)); done
echo "while $i"
if test -f fruits && [ ! -d fruits ]; then echo "test ok"; fi
mkdir -p a/b/c
echo deep > a/b/c/file
ln -s b/c/file a/link
cat a/link
mv a/b/c/file a/b/moved
ls a/b
find a | sort
readlink a/link
rm -r a
ls
mkdir -p src/sub
echo one > src/1.txt
seq 1 100 > src/sub/numbers
tar czf src.tgz src
rm -r src
tar xzf src.tgz
tar tzf src.tgz | sort
cat src/1.txt
tail -n 1 src/sub/numbers
gzip -c fruits | gunzip | head -n 1
ls -l src | awk 'NR > 1 { print $1, $NF }'
readlink /proc/self/exe
head -n 1 /proc/mounts
tr '\0' '\n' < /proc/1/cmdline
ps | awk 'NR == 1 { print $1, $3 } $1 == 1 { print $2, $3, $4 }'
dd if=/dev/zero of=big bs=65536 count=200 2>/dev/null
echo "dd $?"
rm big
echo again > small && cat small
false
echo "false $?"
(exit 7)
echo "subshell $?"
sh -c 'exit 3'
echo "sh $?"
exit 5
