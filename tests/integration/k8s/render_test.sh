#!/usr/bin/env bash
# Both overlays of deploy/k8s render with `kubectl kustomize` and hold what
# the deployment promises: Deployments with requests and limits, HPA and PDB
# for the stateless services, the coordinator as a StatefulSet with a volume
# claim, headless Services, gRPC probes, generated ConfigMaps that the pods
# reference by their hashed names, NetworkPolicies; dev has one replica each
# and pleo_sim, scale three replicas and no pleo_sim.
#   render_test.sh SOURCE_DIR BUILD_DIR
set -euo pipefail
src="$1" build="$2"
command -v kubectl >/dev/null || { echo "SKIP: kubectl not installed (Debian's kubernetes-client)"; exit 77; }
out="$build/k8s-rendered"
mkdir -p "$out"
kubectl version --client 2>/dev/null | head -1 || true
for overlay in dev scale legacy-probes; do
  kubectl kustomize "$src/deploy/k8s/overlays/$overlay" >"$out/$overlay.yaml"
  echo "$overlay: $(grep -c '^kind:' "$out/$overlay.yaml") objects rendered to $out/$overlay.yaml"
done
python3 - "$out" <<'PY'
import re, sys
out = sys.argv[1]

def objects(path):
    # A small reader for kubectl's own output: documents split on '---'; we
    # only need kinds, names and a few fields, so match them in each text.
    return [d for d in open(path).read().split("\n---\n") if d.strip()]

def field(doc, key):
    m = re.search(r"^" + key + r": (.+)$", doc, re.M)
    return m.group(1).strip() if m else None

def name(doc):
    m = re.search(r"^metadata:\n(?:  .*\n)*?  name: (\S+)", doc, re.M)
    return m.group(1)

fail = []
def check(cond, what):
    if not cond: fail.append(what)

for overlay, replicas in (("dev", 1), ("scale", 3), ("legacy-probes", 1)):
    docs = objects(f"{out}/{overlay}.yaml")
    by_kind = {}
    for d in docs:
        by_kind.setdefault(field(d, "kind"), {})[name(d)] = d
    stateless = ["prosody", "inference", "planner", "cube-tracker"]
    for svc in stateless:
        d = by_kind.get("Deployment", {}).get(svc)
        check(d is not None, f"{overlay}: Deployment {svc}")
        if d is None: continue
        check(re.search(r"^  replicas: %d$" % replicas, d, re.M), f"{overlay}: {svc} has {replicas} replicas")
        check("requests:" in d and "limits:" in d, f"{overlay}: {svc} has requests and limits")
        if overlay == "legacy-probes":
            check("kinemo-health" in d and "grpc:" not in d, f"{overlay}: {svc} probes with kinemo-health")
        else:
            check(len(re.findall(r"^\s+grpc:\n\s+port: \d+$", d, re.M)) == 2 and "readinessProbe:" in d
                  and "livenessProbe:" in d, f"{overlay}: {svc} has gRPC readiness and liveness probes")
        check(re.search(r"configMap:\n\s+name: kinemo-config-\w+", d), f"{overlay}: {svc} mounts the hashed kinemo-config")
        check(svc in by_kind.get("HorizontalPodAutoscaler", {}), f"{overlay}: HPA {svc}")
        check(svc in by_kind.get("PodDisruptionBudget", {}), f"{overlay}: PDB {svc}")
        s = by_kind.get("Service", {}).get(svc, "")
        check("clusterIP: None" in s, f"{overlay}: headless Service {svc}")
    sts = by_kind.get("StatefulSet", {}).get("coordinator", "")
    check("volumeClaimTemplates:" in sts, f"{overlay}: coordinator StatefulSet with a volume claim")
    check(re.search(r"configMap:\n\s+name: kinemo-k8s-config-\w+", sts), f"{overlay}: coordinator mounts kinemo-k8s-config")
    rb = by_kind.get("Deployment", {}).get("robot-bridge-pleo", "")
    check(re.search(r"configMap:\n\s+name: robot-bridge-pleo-\w+", rb), f"{overlay}: robot bridge mounts its hashed ConfigMap")
    check(len(by_kind.get("NetworkPolicy", {})) >= 6, f"{overlay}: NetworkPolicies")
    check(all(field(d, "kind") == "Namespace" or "namespace: kinemo" in d for d in docs), f"{overlay}: all in namespace kinemo")
    has_sim = "pleo-sim" in by_kind.get("Deployment", {})
    check(has_sim == (overlay != "scale"), f"{overlay}: pleo-sim only in dev")
    cms = " ".join(by_kind.get("ConfigMap", {}))
    for cm in ("kinemo-config-", "kinemo-k8s-config-", "robot-bridge-pleo-"):
        check(cm in cms, f"{overlay}: ConfigMap {cm}*")
    print(f"{overlay}: " + ", ".join(f"{len(v)} {k}" for k, v in sorted(by_kind.items())))
if fail:
    print("FAIL:\n  " + "\n  ".join(fail))
    sys.exit(1)
PY
echo "PASS: deploy/k8s overlays dev, scale and legacy-probes render"
