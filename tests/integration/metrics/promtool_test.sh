#!/usr/bin/env bash
# deploy/prometheus: both scrape configs are valid, the alert rules load and
# their unit tests pass (promtool from Debian's prometheus package). promtool
# opens the files a config names: the studio's token file
# (/etc/kinemo-secrets/studio-token) is pointed at a temporary one, as the
# launchers point it at theirs.
#   promtool_test.sh SOURCE_DIR
set -euo pipefail
src="$1"
command -v promtool >/dev/null || { echo "SKIP: promtool not installed (Debian's prometheus)"; exit 77; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/secrets"
echo "promtool-test-token-0123456789" >"$tmp/secrets/studio-token"
cp -r "$src/deploy/prometheus/rules" "$src/deploy/prometheus/kinemo.rules.test.yml" "$tmp/"
for f in prometheus.yml prometheus-k8s.yml; do
  sed "s#/etc/kinemo-secrets#$tmp/secrets#g" "$src/deploy/prometheus/$f" >"$tmp/$f"
done
cd "$tmp"
promtool check config prometheus.yml
promtool check config prometheus-k8s.yml
promtool check rules rules/*.yml
promtool test rules kinemo.rules.test.yml
echo "PASS: deploy/prometheus configs and rules"
