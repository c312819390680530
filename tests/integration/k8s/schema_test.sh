#!/usr/bin/env bash
# Every object of the rendered overlays validates against the Kubernetes API
# schemas, offline: deploy/k8s/validate (npm's kubernetes-models, installed
# once into the build folder). Debian has no Kubernetes schema validator
# (kubeconform / kubeval are not packaged); npm's kubernetes-models bundles
# the API's JSON schemas.
#   schema_test.sh SOURCE_DIR BUILD_DIR
set -euo pipefail
src="$1" build="$2"
command -v kubectl >/dev/null || { echo "SKIP: kubectl not installed"; exit 77; }
command -v node >/dev/null && command -v npm >/dev/null || { echo "SKIP: node and npm not installed"; exit 77; }
tool="$build/k8s-validate"
mkdir -p "$tool"
cp "$src/deploy/k8s/validate/package.json" "$src/deploy/k8s/validate/validate.mjs" "$tool/"
if [[ ! -d "$tool/node_modules/kubernetes-models" ]]; then
  (cd "$tool" && npm install --no-audit --no-fund --loglevel=error >npm.log 2>&1) || {
    echo "SKIP: npm install of kubernetes-models failed (registry unreachable?)"; tail -5 "$tool/npm.log"; exit 77; }
fi
for overlay in dev scale legacy-probes; do
  kubectl kustomize "$src/deploy/k8s/overlays/$overlay" >"$tool/$overlay.yaml"
  echo "== $overlay"
  node "$tool/validate.mjs" "$tool/$overlay.yaml"
done
echo "PASS: deploy/k8s overlays validate against the Kubernetes schemas"
