#!/usr/bin/env bash
# Rebuilds the studio page from studio-web/ into beastbt/studio/page/ (commit the result with the sources).
# Needs Node.js and npm, and the npm registry for `npm ci`; tests/test_studio_page.py checks the committed bundle
# was built from these sources (page/BUILD_INFO.json), so tests and `pip install .` need no npm.
set -euo pipefail
cd "$(dirname "$0")"
npm ci --no-audit --no-fund
npm run build
