#!/usr/bin/env bash
# Tests of the browser viewer (docs/viewer.md): builds it (scripts/build-viewer.sh), then
#   reader.test.mjs   Node unit test of the recording reader (round trip, refusals)
#   browser.test.mjs  headless Chromium (/usr/bin/chromium, or $PERCH_CHROMIUM) draws a synthetic
#                     recording; checks the page state and the screenshot pixels (test/out/*.png)
# Exits non-zero when a test fails; a Chromium that cannot start is a failure, never a skip.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
viewer="$(dirname "$here")"
"$viewer/../../scripts/build-viewer.sh"
cd "$viewer"
mkdir -p test/out
status=0
node --test --test-reporter=spec test/reader.test.mjs || status=1
node --test --test-reporter=spec test/browser.test.mjs || status=1
# With the real programs (perch eval --record, perch view): PERCH_BIN, default build/app/perch.
node --test --test-reporter=spec test/perch-view.test.mjs || status=1
if [ "$status" -ne 0 ]; then
  echo "viewer tests: FAILED" >&2
else
  echo "viewer tests: passed (screenshots in $viewer/test/out)"
fi
exit "$status"
