#!/usr/bin/env bash
# Regenerates k8s/configmap.yaml from an experiment config (default: configs/default.json).
set -euo pipefail
cd "$(dirname "$0")/.."
CONFIG=${1:-configs/default.json}
{
  cat <<HDR
# The experiment config, mounted into every pod at /etc/perch/config.json.
# Generated from $CONFIG by scripts/gen-k8s-configmap.sh; a test checks they agree.
apiVersion: v1
kind: ConfigMap
metadata:
  name: perch-config
  labels:
    app: perch
data:
  config.json: |
HDR
  # A config with a `base` is composed first (the pods see only this one file).
  if grep -q '"base"' "$CONFIG"; then
    "${PERCH:-perch}" config --config "$CONFIG" | sed 's/^/    /'
  else
    sed 's/^/    /' "$CONFIG"
  fi
} > k8s/configmap.yaml
echo "wrote k8s/configmap.yaml from $CONFIG"
