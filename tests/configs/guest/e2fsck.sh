#!/bin/sh
# Run in the guest (scenario guest_e2fsck) and on the host in the directory that holds the
# images: Debian's e2fsck.static checks a clean ext4 image and a damaged one, read-only.
cd "${1:-/etc/e2fsck}" || exit 1
for image in clean.img damaged.img; do
    e2fsck -fn "$image" 2>&1
    echo "e2fsck $image: status $?"
done
