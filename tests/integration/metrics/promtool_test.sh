#!/usr/bin/env bash
# deploy/prometheus: the scrape configs (plain and TLS) are valid, the alert rules load and
# their unit tests pass (promtool from Debian's prometheus package). promtool
# opens the files a config names: the studio's token file
# (/etc/kinemo-secrets/studio-token) is pointed at a temporary one, as the
# launchers point it at theirs, and so are the TLS files (/etc/kinemo-tls).
#   promtool_test.sh SOURCE_DIR
set -euo pipefail
src="$1"
command -v promtool >/dev/null || { echo "SKIP: promtool not installed (Debian's prometheus)"; exit 77; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/secrets" "$tmp/tls"
touch "$tmp/tls/ca.pem" "$tmp/tls/prometheus.pem" "$tmp/tls/prometheus.key"
echo "promtool-test-token-0123456789" >"$tmp/secrets/studio-token"
cp -r "$src/deploy/prometheus/rules" "$src/deploy/prometheus/kinemo.rules.test.yml" "$tmp/"
configs=(prometheus.yml prometheus-k8s.yml prometheus-tls.yml prometheus-k8s-tls.yml)
for f in "${configs[@]}"; do
  sed -e "s#/etc/kinemo-secrets#$tmp/secrets#g" -e "s#/etc/kinemo-tls#$tmp/tls#g" "$src/deploy/prometheus/$f" >"$tmp/$f"
done
cd "$tmp"
for f in "${configs[@]}"; do promtool check config "$f"; done
promtool check rules rules/*.yml
promtool test rules kinemo.rules.test.yml
echo "PASS: deploy/prometheus configs and rules"
