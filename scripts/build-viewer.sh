#!/usr/bin/env bash
# Builds the browser viewer of episode recordings (web/viewer, docs/viewer.md) into
# web/viewer/dist/ (index.html, viewer.js, viewer.css): `npm ci` when node_modules is missing or
# package-lock.json changed since the last install, then the esbuild bundle (about a second).
set -euo pipefail
cd "$(dirname "$0")/../web/viewer"
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
  echo "build-viewer: node and npm are needed (scripts/install-deps.sh)" >&2
  exit 1
fi
stamp=node_modules/.perch-package-lock.json
if [ ! -d node_modules ] || ! cmp -s package-lock.json "$stamp"; then
  echo "build-viewer: npm ci"
  # puppeteer-core (tests) never downloads a browser; the tests drive /usr/bin/chromium
  PUPPETEER_SKIP_DOWNLOAD=1 npm ci --no-audit --no-fund
  cp package-lock.json "$stamp"
fi
node build.mjs
