#!/bin/sh
# The disk benchmark of `cargo xtask bench --disk` (tests/configs/bench_disk.toml; the
# native leg runs it as well, on Debian's stock kernel with the same virtio-blk): makes an
# ext2 file system on /dev/vda with busybox mke2fs, mounts it at /data, runs linux-bench's
# disk metrics there (1 MiB written in 64 KiB writes and fsync'd, read back after an
# umount and mount, 4 KiB write + fsync; 3 rounds each) and unmounts it. Arguments go to
# linux-bench (the native leg's `--prefix native_`).
up() { cut -d' ' -f1 /proc/uptime; }
t0=$(up)
mke2fs /dev/vda > /dev/null || { echo "disk-bench: mke2fs failed"; exit 1; }
echo "disk-bench: mke2fs in $(awk -v a="$t0" -v b="$(up)" 'BEGIN { printf "%.2f", b - a }') s"
mkdir -p /data
mount -t ext2 /dev/vda /data || { echo "disk-bench: mount failed"; exit 1; }
/bin/linux-bench --rounds 3 --dir /data --remount /dev/vda --disk-kib 1024 --fsync-loops 20 \
  disk_write_seq disk_read_seq disk_fsync "$@"
status=$?
umount /data || echo "disk-bench: umount failed"
echo "disk-bench: linux-bench status $status"
exit $status
