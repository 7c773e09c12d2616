#!/usr/bin/env bash
# What the browser tests (tests/browser) need from Debian: chromium, and node with npm (for
# playwright-core, which tests/browser/run.sh installs into the build folder at test time).
# Idempotent and quiet when present. A failure here is reported, not fatal: the browser test
# then skips (no chromium) or fails (no node) with a message saying so.
set -uo pipefail
want=()
[ -x /usr/bin/chromium ] || want+=(chromium)
command -v node >/dev/null || want+=(nodejs)
command -v npm >/dev/null || want+=(npm)
[ ${#want[@]} -eq 0 ] && exit 0
echo "install-browser-deps: installing ${want[*]}"
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO=sudo
export DEBIAN_FRONTEND=noninteractive
if ! { $SUDO apt-get update -qq &&
       $SUDO apt-get install -y -qq --no-install-recommends "${want[@]}" >/dev/null; }; then
  echo "install-browser-deps: could not install ${want[*]}; the browser tests will say so" >&2
  exit 1
fi
