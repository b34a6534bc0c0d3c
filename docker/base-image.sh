#!/usr/bin/env bash
# Makes the local base image idms-base:bookworm once (no registry is reachable): a minimal
# Debian bookworm from the mirror this machine's apt already uses, by debootstrap, then
# `docker import`. Reused when it exists. Needs DOCKER_HOST (docker/dockerd.sh) and root.
set -euo pipefail
docker_bin="${IDMS_DOCKER_CLIENT:-/usr/bin/docker}"
image=idms-base:bookworm
if "$docker_bin" image inspect "$image" >/dev/null 2>&1; then
  echo "base-image: $image present"
  exit 0
fi
# The first deb URI of the machine's sources (deb822 or one-line format).
mirror=$(sed -n 's/^URIs: *\([^ ]*\).*/\1/p' /etc/apt/sources.list.d/debian.sources 2>/dev/null | head -1)
[ -n "$mirror" ] || mirror=$(awk '$1 == "deb" {print $2; exit}' /etc/apt/sources.list 2>/dev/null || true)
mirror="${mirror:-http://deb.debian.org/debian}"
root="${IDMS_DOCKER_STATE:-/var/tmp/idms-docker}/rootfs"
rm -rf "$root"
echo "base-image: debootstrap --variant=minbase bookworm from $mirror"
debootstrap --variant=minbase bookworm "$root" "$mirror" > "$root.log" 2>&1 || {
  tail -20 "$root.log"; exit 1; }
# apt inside the image uses the same mirror (and the security suite next to it, when known).
echo "deb $mirror bookworm main" > "$root/etc/apt/sources.list"
tar -C "$root" -c . | "$docker_bin" import - "$image"
rm -rf "$root"
echo "base-image: $image made"
