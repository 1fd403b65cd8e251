#!/bin/sh
# Makes the two ext4 images of scenario guest_e2fsck in target/guest-e2fsck (run by
# `cargo xtask test` from the workspace root before the image is assembled): clean.img, made
# by mkfs.ext4 with a fixed UUID and hash seed from a small tree (a directory, a file of two
# thousand lines, a symbolic link), and damaged.img, a copy that debugfs gives a wrong link
# count and an allocated block marked free.
set -eu
dir=target/guest-e2fsck
rm -rf "$dir"
mkdir -p "$dir/tree/docs"
cd "$dir"
echo "setpoint 50" > tree/docs/plant.txt
seq 1 2000 > tree/numbers.txt
ln -s docs/plant.txt tree/link
uuid=6d2c1e0a-1b2c-4d3e-8f90-a1b2c3d4e5f6
truncate -s 1M clean.img
mkfs.ext4 -q -F -U "$uuid" -E "root_owner=0:0,hash_seed=$uuid" -d tree clean.img 2>/dev/null
cp clean.img damaged.img
debugfs -w -R "set_inode_field /numbers.txt links_count 5" damaged.img 2>/dev/null
first=$(debugfs -R "blocks /numbers.txt" clean.img 2>/dev/null | cut -d' ' -f1)
debugfs -w -R "freeb $first" damaged.img 2>/dev/null
