#!/usr/bin/env bash
# Runs the browser tests: installs playwright-core (pinned by package-lock.json) into
# BUILD/browser/node on first use, then drives Debian's chromium against `ptmkit view`.
# Usage: tests/browser/run.sh PTMKIT BUILD_DIR
# Exit codes: 0 passed, 1 failed, 77 skipped (no chromium on this machine: the message says
# how to install it).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
ptmkit="$1"
work="$2/browser"
chromium="${PTMKIT_CHROMIUM:-/usr/bin/chromium}"
if [ ! -x "$chromium" ]; then
  echo "SKIP: no Chromium at $chromium (install Debian's chromium: scripts/install-deps.sh" \
       "installs it; or set PTMKIT_CHROMIUM)"
  exit 77
fi
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
  echo "FAIL: node and npm are needed for the browser tests (scripts/install-deps.sh installs them)"
  exit 1
fi
mkdir -p "$work/node"
if ! cmp -s "$here/package-lock.json" "$work/node/package-lock.json" ||
   [ ! -d "$work/node/node_modules/playwright-core" ]; then
  cp "$here/package.json" "$here/package-lock.json" "$work/node/"
  (cd "$work/node" && npm ci --no-audit --no-fund --loglevel=error)
fi
exec node "$here/viewer_test.mjs" "$ptmkit" "$work" "$chromium"
