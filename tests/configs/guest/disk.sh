#!/bin/sh
# Scenario store_guest_disk (tests/configs/store_guest.toml): the guest's /dev/vda, its
# virtual disk of the block-device partition. On a fresh disk (no marker at byte 2090000)
# it makes an ext2 file system with busybox mke2fs, writes the marker (1000 bytes, across
# sector boundaries) to the raw device with dd and syncs; on the disk of an earlier boot it
# reads the marker back. Both check the file system with Debian's e2fsck.static -fn.
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
t0=$(up)
e2fsck -fn /dev/vda
status=$?
echo "e2fsck status $status in $(since "$t0") s"
