#!/usr/bin/env bash
# Builds the kinemo runtime image here, where no registry is reachable: the
# root file system is made from the local build (make-rootfs.sh) and imported
# with `podman import` as localhost/kinemo/runtime:latest. Every compose
# service runs this one image with its own command.
#   deploy/container/build-images.sh [BUILD_DIR]
# Users with Docker and a registry build the same image from the Dockerfile:
#   docker build -f deploy/container/Dockerfile -t localhost/kinemo/runtime:latest .
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
build="${1:-$root/build}"
image="${KINEMO_IMAGE:-localhost/kinemo/runtime:latest}"
command -v podman >/dev/null || { echo "build-images: podman is not installed (deploy/install-deps.sh)" >&2; exit 2; }
source "$here/podman-env.sh"
kinemo_podman_start >/dev/null  # writes containers.conf (the image store is podman's own)
kinemo_podman_stop
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
bash "$here/make-rootfs.sh" "$build" "$work/rootfs"
tar -C "$work/rootfs" -cf "$work/rootfs.tar" .
podman import \
  --change 'WORKDIR /var/lib/kinemo' \
  --change 'USER 10001' \
  --change 'ENV LD_LIBRARY_PATH=' \
  --message "kinemo runtime from $build" \
  "$work/rootfs.tar" "$image" >/dev/null
echo "build-images: $image ($(podman image inspect --format '{{.Size}}' "$image" | awk '{printf "%.0f MB", $1/1e6}'))"
