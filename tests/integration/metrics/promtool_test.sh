#!/usr/bin/env bash
# deploy/prometheus: both scrape configs are valid, the alert rules load and
# their unit tests pass (promtool from Debian's prometheus package).
#   promtool_test.sh SOURCE_DIR
set -euo pipefail
src="$1"
command -v promtool >/dev/null || { echo "SKIP: promtool not installed (Debian's prometheus)"; exit 77; }
cd "$src/deploy/prometheus"
promtool check config prometheus.yml
promtool check config prometheus-k8s.yml
promtool check rules rules/*.yml
promtool test rules kinemo.rules.test.yml
echo "PASS: deploy/prometheus configs and rules"
