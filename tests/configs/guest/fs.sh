#!/bin/sh
# Scenario store_guest_fs (tests/configs/store_guest.toml): the guest's /dev/vda, its
# virtual disk of the block-device partition, and the ext2 file system on it at /data.
# On a fresh disk (no marker at byte 2090000) it makes an ext2 file system with busybox
# mke2fs, writes the marker (1000 bytes, across sector boundaries) to the raw device with
# dd and syncs; on the disk of an earlier boot it reads the marker back. Then it mounts the
# file system at /data (by its type on the first boot, without it on the second): on the
# first boot it writes a file 20 times by write, fsync and rename, writes 300 KiB with its
# checksum and changes a directory (links, a symbolic link, a removal); on the second it
# reads all of that back. Both unmount it (busy while the shell is in /data) and check it
# with Debian's e2fsck.static -fn.
up() { cut -d' ' -f1 /proc/uptime; }
since() { awk -v a="$1" -v b="$(up)" 'BEGIN { printf "%.2f", b - a }'; }
seq 1 300 | tr '\n' ' ' | head -c 1000 > /tmp/marker
stat -c 'vda: %F %t:%T size %s' /dev/vda
echo "blockdev: $(blockdev --getsize64 /dev/vda) bytes, $(blockdev --getsz /dev/vda) sectors of $(blockdev --getss /dev/vda)"
echo "ports: $(ls /dev/arinc | wc -l) in /dev/arinc"
echo "past the end: $(dd if=/dev/vda bs=512 skip=4096 count=1 2>/dev/null | wc -c) bytes read"
if echo x | dd of=/dev/vda bs=512 seek=4096 conv=notrunc 2>/tmp/err; then
  echo "past the end: written"
else
  echo "past the end: $(grep -o 'No space left on device' /tmp/err)"
fi
if dd if=/dev/vda bs=1000 skip=2090 count=1 2>/dev/null | cmp -s - /tmp/marker; then
  echo "second boot: marker read back"
  second=yes
else
  echo "first boot"
  t0=$(up)
  mke2fs /dev/vda > /tmp/mke2fs.out
  status=$?
  echo "mke2fs status $status in $(since "$t0") s"
  dd if=/tmp/marker of=/dev/vda bs=1000 seek=2090 conv=notrunc,fsync 2>/dev/null
  echo "dd status $?"
  sync
  echo "synced"
fi
mkdir -p /data
t0=$(up)
if [ "$second" ]; then
  mount /dev/vda /data # the type found by trying /proc/filesystems
else
  mount -t ext2 /dev/vda /data
fi
echo "mount status $? in $(since "$t0") s"
grep ' /data ' /proc/mounts
if [ -f /data/state ]; then
  echo "state: $(cat /data/state)"
  (cd /data && md5sum -c big.md5 > /dev/null) && echo "big: intact"
  echo "dir: $(ls /data/dir | tr '\n' ' ')$(readlink /data/dir/c)"
else
  t0=$(up)
  i=0
  while [ $i -lt 20 ]; do
    echo "version $i" > /data/state.tmp && sync /data/state.tmp &&
      mv /data/state.tmp /data/state || echo "replace $i failed"
    i=$((i + 1))
  done
  echo "replace loop in $(since "$t0") s"
  echo "state: $(cat /data/state)"
  t0=$(up)
  dd if=/dev/urandom of=/data/big bs=1024 count=300 2> /dev/null
  (cd /data && md5sum big > big.md5)
  sync /data/big /data/big.md5
  echo "big written in $(since "$t0") s"
  mkdir /data/dir && echo a > /data/dir/a && ln /data/dir/a /data/dir/b &&
    ln -s a /data/dir/c && rm /data/dir/b && echo "dir: changed"
fi
df -k /data | awk 'NR == 2 { print "df: " $2 " KiB, " $4 " KiB free" }'
cd /data && umount /data 2> /dev/null || echo "umount while in /data: refused"
cd /
t0=$(up)
umount /data
echo "umount status $? in $(since "$t0") s"
t0=$(up)
e2fsck -fn /dev/vda
status=$?
echo "e2fsck status $status in $(since "$t0") s"
