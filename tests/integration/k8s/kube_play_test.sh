#!/usr/bin/env bash
# `podman kube play` of the dev overlay: the rendered manifests (its
# legacy-probes variant: podman runs exec probes, not Kubernetes' gRPC probe)
# run on this machine from the runtime image of deploy/container, and the
# Vleo scenario passes through them: a session opened at the coordinator
# makes the robot bridge drive pleo_sim over Modbus, and kisses turn an angry
# Pleo neutral; `kinemo animate --method gc` crosses prosody, inference and
# planner. Podman has no Services, StatefulSets or Secret volumes:
# k8s_pod.py folds the overlay's workloads (same image, commands, ConfigMaps,
# probes, resources) into one pod whose hostAliases resolve the Services'
# DNS names to that pod's loopback, and drops the optional TLS Secret. The
# CLI runs inside the pod (`podman exec`): no host port is used.
# Skipped with 77 where podman (as root) or kubectl cannot run.
#   kube_play_test.sh SOURCE_DIR BUILD_DIR
set -euo pipefail
src="$1" build="$2"
command -v kubectl >/dev/null || { echo "SKIP: kubectl not installed"; exit 77; }
source "$src/deploy/container/podman-env.sh"
kinemo_podman_test_ready
# The containers.conf this machine needs (runc, cgroupfs, file events, open
# files within the hard limit): podman-env.sh writes it and exports
# CONTAINERS_CONF; the API service it starts is not needed here.
kinemo_podman_start >/dev/null
kinemo_podman_stop
work="$(mktemp -d)"
tag="kubeplay$$"
# The image of ctest's fixture (podman_image.sh), or one of the test's own.
export KINEMO_IMAGE="${KINEMO_TEST_IMAGE:-localhost/kinemo/runtime:$tag}"
pod="kinemo-dev-$tag"
# Podman 4.3 turns each ConfigMap into a volume of the same name and `kube
# down` leaves it behind. The names repeat from run to run (kustomize's
# content hash, studio-token), so a leftover would be reused: an old token,
# and after /dev/shm is reset (a reboot) a lock ID podman hands out again
# ("container and volume share lock ID 5: deadlock due to lock mismatch").
# So the test removes them before it plays and when it ends.
remove_config_volumes() {
  [[ -f "$work/pod.yaml" ]] || return 0
  local v
  for v in $(python3 -c 'import sys, yaml
for d in yaml.safe_load_all(open(sys.argv[1])):
    if d and d["kind"] == "ConfigMap": print(d["metadata"]["name"])' "$work/pod.yaml"); do
    podman volume rm -f "$v" >/dev/null 2>&1 || true
  done
}
cleanup() {
  local rc=$?
  if [[ $rc != 0 && -f "$work/pod.yaml" ]]; then
    for c in coordinator robot-bridge pleo-sim; do
      echo "--- $c log"; podman logs --tail 15 "$pod-$c" 2>&1 || true
    done
  fi
  [[ -f "$work/pod.yaml" ]] && podman kube down "$work/pod.yaml" >/dev/null 2>&1 || true
  remove_config_volumes
  [[ -n "${KINEMO_TEST_IMAGE:-}" ]] || podman rmi -f "$KINEMO_IMAGE" >/dev/null 2>&1 || true
  rm -rf "$work"
  exit $rc
}
trap cleanup EXIT

if [[ -z "${KINEMO_TEST_IMAGE:-}" ]] || ! podman image exists "$KINEMO_IMAGE"; then
  bash "$src/deploy/container/build-images.sh" "$build"
fi
kubectl kustomize "$src/deploy/k8s/overlays/legacy-probes" >"$work/dev.yaml"
python3 "$src/tests/integration/k8s/k8s_pod.py" "$work/dev.yaml" "$pod" "$KINEMO_IMAGE" >"$work/pod.yaml"
remove_config_volumes
podman kube play "$work/pod.yaml"

in_pod() { podman exec "$pod-coordinator" "$@"; }
for target in coordinator:localhost:50050 robot-bridge:localhost:50055 prosody:localhost:50051 \
              inference:localhost:50052 planner:localhost:50053 cube-tracker:localhost:50054 pleo-sim:--tcp; do
  name="${target%%:*}" addr="${target#*:}"
  ok=0
  for _ in $(seq 1 120); do
    if [[ "$addr" == --tcp ]]; then in_pod /usr/local/bin/kinemo-health --tcp localhost:1502 --timeout-s 1 2>/dev/null && { ok=1; break; }
    else in_pod /usr/local/bin/kinemo-health "$addr" --timeout-s 1 2>/dev/null && { ok=1; break; }; fi
    sleep 0.5
  done
  [[ $ok == 1 ]] || { echo "FAIL: $name is not serving in the pod"; podman logs --tail 20 "$pod-$name" || true; exit 1; }
  echo "kube play: $name serving"
done

kinemo=(podman exec "$pod-coordinator" /usr/local/bin/kinemo)
# The Vleo scenario through the pod's coordinator, robot bridge and pleo_sim.
"${kinemo[@]}" session open pleo --id kubeplay --initial angry --coordinator localhost:50050
deadline=$((SECONDS + 20))
until "${kinemo[@]}" robot status pleo --bridge localhost:50055 | grep -q "shows angry"; do
  (( SECONDS < deadline )) || { echo "FAIL: the session did not make Pleo angry"; exit 1; }
  sleep 0.3
done
"${kinemo[@]}" session act kubeplay kisses -i 1 --coordinator localhost:50050
deadline=$((SECONDS + 40))
until "${kinemo[@]}" robot status pleo --bridge localhost:50055 | grep -q "shows neutral"; do
  (( SECONDS < deadline )) || { echo "FAIL: Pleo did not turn neutral within 40 s of kisses"; exit 1; }
  sleep 0.5
done
"${kinemo[@]}" session close kubeplay --coordinator localhost:50050
# Speech -> motion through the coordinator's dns:/// channels (round_robin)
# to prosody, inference and planner: the Gesture Controller on a recording.
podman cp "$src/tests/data/speech/sense_and_sensibility_01_austen_64kb-0880.wav" "$pod-coordinator:/tmp/speech.wav"
"${kinemo[@]}" animate /tmp/speech.wav -o /tmp/out.bvh --coordinator localhost:50050 --method gc
"${kinemo[@]}" bvh info /tmp/out.bvh | grep "^frames:" >/dev/null || { echo "FAIL: no BVH from animate in the pod"; exit 1; }
echo "PASS: podman kube play ran the dev overlay; the Vleo scenario turned Pleo from angry to neutral; animate crossed prosody, inference and planner"
