#!/usr/bin/env bash
# The runtime image the three podman tests share (deploy_compose_podman,
# deploy_compose_podman_tls, k8s_podman_kube_play): a ctest fixture builds it
# once from BUILD_DIR before the first of them and removes it after the last
# (tests/integration/deploy/CMakeLists.txt). Each test built its own before
# (about 12 s each, inside the heavy tests' lock). Run by hand, those tests
# still build and remove an image of their own (KINEMO_TEST_IMAGE unset).
# Skipped with 77 where podman (as root) cannot run; the tests then skip too.
#   podman_image.sh build|remove SOURCE_DIR BUILD_DIR IMAGE
set -euo pipefail
action="$1" src="$2" build="$3" image="$4"
source "$src/deploy/container/podman-env.sh"
case "$action" in
  build)
    kinemo_podman_test_ready
    KINEMO_IMAGE="$image" bash "$src/deploy/container/build-images.sh" "$build"
    ;;
  remove)
    command -v podman >/dev/null || exit 0
    if podman image exists "$image" 2>/dev/null; then
      podman rmi -f "$image" >/dev/null
      echo "podman_image: removed $image"
    fi
    ;;
  *) echo "usage: podman_image.sh build|remove SOURCE_DIR BUILD_DIR IMAGE" >&2; exit 2 ;;
esac
