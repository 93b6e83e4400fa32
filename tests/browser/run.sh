#!/usr/bin/env bash
# The dashboard's browser test, as CI runs it:
#
#   tests/browser/run.sh BASE_URL OUT_DIR
#
# Installs Debian's chromium when /usr/bin/chromium is missing and playwright-core (which never
# downloads a browser) into tests/browser/node_modules, then runs docs.mjs (the API's /docs page)
# and dashboard.mjs against a running
# `bouncewear serve` at BASE_URL. Screenshots go to OUT_DIR. Set BOUNCEWEAR_API_KEY when the server
# has keys.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
base="${1:?usage: run.sh BASE_URL OUT_DIR}"
out="${2:?usage: run.sh BASE_URL OUT_DIR}"

if [ ! -x /usr/bin/chromium ]; then
  if ! command -v apt-get >/dev/null 2>&1; then
    echo "run.sh: /usr/bin/chromium is missing and there is no apt-get to install it" >&2
    exit 1
  fi
  sudo=""
  if [ "$(id -u)" != 0 ]; then
    if command -v sudo >/dev/null 2>&1; then sudo="sudo"; else
      echo "run.sh: /usr/bin/chromium is missing and installing it needs root" >&2
      exit 1
    fi
  fi
  echo "run.sh: installing Debian's chromium" >&2
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq >/dev/null
  $sudo apt-get install -y -qq --no-install-recommends chromium >/dev/null
fi

if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  echo "run.sh: node and npm are needed for the browser test" >&2
  exit 1
fi

# The version package.json pins; reinstall when node_modules holds another one.
wanted="$(node -p "require('$here/package.json').dependencies['playwright-core']")"
installed="$(node -p "try { require('$here/node_modules/playwright-core/package.json').version } catch (e) { '' }")"
if [ "$installed" != "$wanted" ]; then
  echo "run.sh: installing playwright-core $wanted" >&2
  (cd "$here" && PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm install --no-package-lock --no-audit --no-fund \
    --loglevel=error >/dev/null)
fi

mkdir -p "$out"
node "$here/docs.mjs" "$base"
exec node "$here/dashboard.mjs" "$base" "$out"
