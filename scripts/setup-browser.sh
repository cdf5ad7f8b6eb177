#!/bin/sh
# Headless Chromium for the viewer's browser test (tests/test_viewer.py): the distribution's
# package, installed only when missing (idempotent). Prints the browser's path on stdout and
# exits 0, or says on stderr why it cannot be installed and exits 1 (the tests then skip).
# About 480 MB installed (Debian bookworm's chromium with chromium-common and its libraries).
set -u
find_browser() {
    for name in chromium chromium-browser; do
        if command -v "$name" >/dev/null 2>&1; then command -v "$name"; return 0; fi
    done
    return 1
}
if find_browser; then exit 0; fi
if ! command -v apt-get >/dev/null 2>&1; then
    echo "setup-browser: chromium is not installed and there is no apt-get to install it" >&2; exit 1
fi
if [ "$(id -u)" -ne 0 ]; then
    echo "setup-browser: chromium is not installed; installing it needs root (apt-get install chromium)" >&2; exit 1
fi
export DEBIAN_FRONTEND=noninteractive
if ! apt-get install -y --no-install-recommends chromium >/dev/null 2>&1; then
    apt-get update >/dev/null 2>&1
    if ! apt-get install -y --no-install-recommends chromium >/dev/null 2>&1; then
        echo "setup-browser: apt-get install chromium failed (no network or no such package?)" >&2; exit 1
    fi
fi
find_browser || { echo "setup-browser: chromium installed but not found on PATH" >&2; exit 1; }
