#!/usr/bin/env python3
"""Folds a rendered kinemo overlay (kubectl kustomize output) into what
`podman kube play` (podman 4.3) runs: one Pod with every workload's
containers, the ConfigMaps they mount, and hostAliases that resolve every
Service's DNS names to the pod's loopback (podman has no Services). Secret
volumes (optional TLS material) are dropped but the studio's token (Secret
studio-token), which becomes a ConfigMap with a new random token; volume
claims become emptyDirs,
volume names get their workload's prefix, and the image is replaced.
    k8s_pod.py RENDERED.yaml POD_NAME IMAGE > pod.yaml
(PyYAML: Debian's python3-yaml.)"""
import secrets
import sys

import yaml

rendered, pod_name, image = sys.argv[1:]
docs = [d for d in yaml.safe_load_all(open(rendered)) if d]
config_maps = [d for d in docs if d["kind"] == "ConfigMap"]
names = []
for d in docs:
    if d["kind"] == "Service":
        n, ns = d["metadata"]["name"], d["metadata"].get("namespace", "default")
        names += [n, f"{n}.{ns}", f"{n}.{ns}.svc", f"{n}.{ns}.svc.cluster.local"]
containers, volumes = [], []
for d in docs:
    if d["kind"] not in ("Deployment", "StatefulSet"):
        continue
    workload = d["metadata"]["name"]
    spec = d["spec"]["template"]["spec"]
    claims = {c["metadata"]["name"] for c in d["spec"].get("volumeClaimTemplates", [])}
    kept = {}
    for v in spec.get("volumes", []):
        if "secret" in v and v["secret"].get("secretName") == "studio-token":
            # Podman has no Secret volumes: the same file from a ConfigMap.
            config_maps.append({"apiVersion": "v1", "kind": "ConfigMap",
                                "metadata": {"name": f"{workload}-studio-token"},
                                "data": {"studio-token": secrets.token_hex(24)}})
            kept[v["name"]] = {"name": f"{workload}-{v['name']}", "configMap": {"name": f"{workload}-studio-token"}}
            continue
        if "secret" in v:
            continue
        kept[v["name"]] = dict(v, name=f"{workload}-{v['name']}")
    for claim in claims:
        kept[claim] = {"name": f"{workload}-{claim}", "emptyDir": {}}
    volumes += kept.values()
    for c in spec["containers"]:
        c = dict(c, image=image)
        c["volumeMounts"] = [dict(m, name=kept[m["name"]]["name"]) for m in c.get("volumeMounts", [])
                             if m["name"] in kept]
        # One network namespace: the ports stay distinct, as in the overlay.
        c["securityContext"] = {"runAsUser": spec.get("securityContext", {}).get("runAsUser", 10001)}
        containers.append(c)
pod = {
    "apiVersion": "v1",
    "kind": "Pod",
    "metadata": {"name": pod_name, "labels": {"app.kubernetes.io/part-of": "kinemo"}},
    "spec": {
        "hostAliases": [{"ip": "127.0.0.1", "hostnames": names}],
        "containers": containers,
        "volumes": volumes,
        "restartPolicy": "Always",
    },
}
for cm in config_maps:
    cm["metadata"].pop("namespace", None)
yaml.safe_dump_all(config_maps + [pod], sys.stdout, sort_keys=False)
