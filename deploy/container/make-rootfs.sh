#!/usr/bin/env bash
# Makes the root file system of the kinemo runtime image from a build tree:
# every service binary, the kinemo tools, the shared libraries they load
# (found with ldd), the CMU Sphinx models, and a minimal /etc.
#   deploy/container/make-rootfs.sh BUILD_DIR OUT_DIR
# Used by the Dockerfile (runtime stage) and by build-images.sh (podman import).
set -euo pipefail
build="$(realpath "${1:?usage: make-rootfs.sh BUILD_DIR OUT_DIR}")"
out="${2:?usage: make-rootfs.sh BUILD_DIR OUT_DIR}"
rm -rf "$out"
# var/lib/kinemo/<service>: the artifact stores and the coordinator's session
# store (volumes copy this ownership), and media/studio: the studio's cube
# videos (its cube_dir, a volume the cube tracker reads). Libraries,
# libsqlite3 included, come from ldd below.
mkdir -p "$out"/usr/local/bin "$out"/etc "$out"/tmp "$out"/var/lib/kinemo "$out"/etc/kinemo \
  "$out"/var/lib/kinemo/inference "$out"/var/lib/kinemo/planner "$out"/var/lib/kinemo/cube_tracker \
  "$out"/var/lib/kinemo/coordinator "$out"/var/lib/kinemo/media/studio
chmod 1777 "$out"/tmp

binaries=(
  services/prosody/prosody services/inference/inference services/planner/planner
  services/cube_tracker/cube_tracker services/robot_bridge/robot_bridge
  services/pleo_sim/pleo_sim services/coordinator/coordinator
  services/allinone/kinemo_allinone services/studio/studio
  services/cli/kinemo services/cli/kinemo-vision services/cli/kinemo-bench services/cli/kinemo-health
)
copied=0
for b in "${binaries[@]}"; do
  if [[ ! -x "$build/$b" ]]; then
    echo "make-rootfs: $b not built, left out" >&2
    continue
  fi
  install -m 0755 "$build/$b" "$out/usr/local/bin/"
  copied=$((copied + 1))
  # Shared libraries (and the loader), at their own paths, symlinks resolved.
  while read -r lib; do
    [[ -e "$out$lib" ]] && continue
    mkdir -p "$out$(dirname "$lib")"
    cp -L "$lib" "$out$lib"
  done < <(ldd "$build/$b" | grep -o '/[^ ]*' | sort -u)
done
[[ $copied -gt 0 ]] || { echo "make-rootfs: no binaries in $build" >&2; exit 1; }
# The loader is also looked up through /lib64 on x86-64.
if [[ -e /lib64/ld-linux-x86-64.so.2 && ! -e "$out/lib64/ld-linux-x86-64.so.2" ]]; then
  mkdir -p "$out/lib64"
  cp -L /lib64/ld-linux-x86-64.so.2 "$out/lib64/"
fi
# CMU Sphinx models (prosody keywords and phones).
if [[ -d /usr/share/pocketsphinx/model/en-us ]]; then
  mkdir -p "$out/usr/share/pocketsphinx/model"
  cp -r /usr/share/pocketsphinx/model/en-us "$out/usr/share/pocketsphinx/model/"
fi
# The bundled gesture data (licences inside): BEAT2's conversational takes
# (the default library "bundled") and the Bandai clips (library "bandai",
# CC BY-NC 4.0): the planner's preloads and `kinemo animate`'s embedded default.
src="$(cd "$(dirname "$0")/../.." && pwd)"
mkdir -p "$out/usr/local/share/kinemo/gestures/user" "$out/usr/local/share/kinemo/gestures/paired"
for d in paired/beat2 planner_gesture planner_controller; do
  if [[ -d "$src/tests/data/$d" ]]; then cp -r "$src/tests/data/$d" "$out/usr/local/share/kinemo/gestures/$d"; fi
done
# The bundled artifact store (deploy/seed-store.sh, made by the build): the
# services' seed_store_dir — the default Gesture Controller and gesture graph.
if [[ -d "$build/share/kinemo/store" ]]; then
  mkdir -p "$out/usr/local/share/kinemo"
  cp -r "$build/share/kinemo/store" "$out/usr/local/share/kinemo/store"
else
  echo "make-rootfs: $build/share/kinemo/store not built (target kinemo_seed_store), left out" >&2
fi
# The web studio's page (built into share/kinemo/studio), its libraries
# (share/kinemo/studio-libs: three.js and three-vrm bundled from npm, the
# Draco decoder) and the sample recordings the page offers.
if [[ -d "$build/share/kinemo/studio" ]]; then
  mkdir -p "$out/usr/local/share/kinemo/samples"
  cp -r "$build/share/kinemo/studio" "$out/usr/local/share/kinemo/studio"
  cp -r "$build/share/kinemo/studio-libs" "$out/usr/local/share/kinemo/studio-libs"
  if [[ -d "$build/share/kinemo/characters" ]]; then
    cp -r "$build/share/kinemo/characters" "$out/usr/local/share/kinemo/characters"
  fi
  cp "$src"/tests/data/speech/*.wav "$out/usr/local/share/kinemo/samples/"
  # The cube the studio attaches (vleo.cube) and its bundled scenarios (the
  # render scripts it draws on first use; their backgrounds are ../images/).
  cp -r "$src/tests/data/cube" "$out/usr/local/share/kinemo/cube"
  cp -r "$src/tests/data/images" "$out/usr/local/share/kinemo/images"
fi
printf 'root:x:0:0:root:/root:/usr/sbin/nologin\nkinemo:x:10001:10001:kinemo:/var/lib/kinemo:/usr/sbin/nologin\n' >"$out/etc/passwd"
printf 'root:x:0:\nkinemo:x:10001:\n' >"$out/etc/group"
printf 'hosts: files dns\n' >"$out/etc/nsswitch.conf"
chown -R 10001:10001 "$out/var/lib/kinemo" 2>/dev/null || true
echo "make-rootfs: $copied binaries, $(du -sh "$out" | cut -f1) in $out"
