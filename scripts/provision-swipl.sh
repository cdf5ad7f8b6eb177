#!/usr/bin/env bash
# Find or build a SWI-Prolog >= 9.1.12 and print its home directory's `swipl` path.
#
# Order (first hit wins):
#   1. $SWIPL, if set (must be >= 9.1.12, else we stop with an error);
#   2. a `swipl` on PATH that is >= 9.1.12;
#   3. the per-user cache ${SPAR_CACHE:-~/.cache/spar-py}/swipl-<version>/bin/swipl;
#   4. build SWI-Prolog 9.2.x from the distribution's source package:
#      a temporary apt configuration (its own sources file, lists and archives
#      directories, never touching /etc/apt) names the next release's deb-src with
#      the mirror URI read from this machine's apt configuration; `apt-get source
#      --download-only --tar-only swi-prolog` fetches the upstream tarball; the build
#      dependencies come from apt-get; cmake+ninja build it with X11, Java, ODBC, BDB
#      and documentation off and install it into the cache.
# All progress goes to stderr; the only line on stdout is the path of the swipl binary.
set -euo pipefail

MIN_VERSION=90112          # 9.1.12, janus-swi's floor
CACHE=${SPAR_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/spar-py}
log() { printf 'provision-swipl: %s\n' "$*" >&2; }
die() { log "error: $*"; exit 1; }

# version_of SWIPL -> prints the numeric version (e.g. 90209) or nothing
version_of() {
    "$1" --dump-runtime-variables 2>/dev/null | sed -n 's/^PLVERSION="\([0-9]*\)";$/\1/p'
}

if [ -n "${SWIPL:-}" ]; then
    v=$(version_of "$SWIPL") || true
    [ -n "$v" ] || die "SWIPL=$SWIPL does not run as a SWI-Prolog binary"
    [ "$v" -ge "$MIN_VERSION" ] || die "SWIPL=$SWIPL is version $v; janus-swi needs >= $MIN_VERSION"
    command -v "$SWIPL"; exit 0
fi

if p=$(command -v swipl 2>/dev/null); then
    v=$(version_of "$p") || true
    if [ -n "$v" ] && [ "$v" -ge "$MIN_VERSION" ]; then
        log "using $p (version $v)"; echo "$p"; exit 0
    fi
    log "ignoring $p (version ${v:-unknown} < $MIN_VERSION)"
fi

for p in $(ls -d "$CACHE"/swipl-*/bin/swipl 2>/dev/null | sort -rV); do
    v=$(version_of "$p") || true
    if [ -n "$v" ] && [ "$v" -ge "$MIN_VERSION" ]; then
        log "using cached $p (version $v)"; echo "$p"; exit 0
    fi
done

# ---- build from the distribution's source package --------------------------------
[ -r /etc/os-release ] || die "no /etc/os-release: cannot tell the distribution; install SWI-Prolog >= 9.1.12 and set SWIPL=/path/to/swipl"
. /etc/os-release
# The release after this one, whose swi-prolog source package is 9.2.x.
# SPAR_SWIPL_SUITE overrides it (for distributions not listed here).
case "${SPAR_SWIPL_SUITE:-${VERSION_CODENAME:-}}" in
    bookworm) suite=trixie ;;
    noble|oracular|plucky) suite=questing ;;
    "") die "unknown release; set SPAR_SWIPL_SUITE to a suite whose swi-prolog is 9.2.x" ;;
    *) suite=${SPAR_SWIPL_SUITE:-} ;;
esac
[ -n "$suite" ] || die "no known next release for '$VERSION_CODENAME'; set SPAR_SWIPL_SUITE"

# The mirror: the first URI of the distribution's own archive in the apt configuration.
mirror=$( { cat /etc/apt/sources.list.d/*.sources 2>/dev/null | sed -n 's/^URIs:[[:space:]]*//p' | tr ' ' '\n';
            cat /etc/apt/sources.list /etc/apt/sources.list.d/*.list 2>/dev/null \
              | sed -n 's/^deb[[:space:]]\+\(\[[^]]*\][[:space:]]\+\)\?\([^[:space:]]*\).*/\2/p'; } \
          | grep -E '/(debian|ubuntu)/?$' | grep -v -- '-security' | head -n 1 || true)
[ -n "$mirror" ] || die "no Debian/Ubuntu mirror URI found in /etc/apt; set SWIPL=/path/to/swipl (>= 9.1.12)"
case "$ID" in
    ubuntu) keyring=/usr/share/keyrings/ubuntu-archive-keyring.gpg ;;
    *)      keyring=/usr/share/keyrings/debian-archive-keyring.gpg ;;
esac
log "building SWI-Prolog from $suite's source package via $mirror"

SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO=sudo
deps="build-essential cmake ninja-build pkg-config libgmp-dev libssl-dev zlib1g-dev
      libreadline-dev libedit-dev libncurses-dev libpcre2-dev libarchive-dev libyaml-dev
      uuid-dev python3-dev xz-utils dpkg-dev"
missing=""
for d in $deps; do dpkg -s "$d" >/dev/null 2>&1 || missing="$missing $d"; done
if [ -n "$missing" ]; then
    log "installing build dependencies:$missing"
    $SUDO apt-get update -qq >&2
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing >&2
fi

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/lists/partial" "$work/archives/partial" "$work/src"
cat > "$work/sources.list" <<SRC
deb-src [signed-by=$keyring] $mirror $suite main
SRC
apt_opts=(-o "Dir::Etc::SourceList=$work/sources.list" -o "Dir::Etc::SourceParts=/dev/null"
          -o "Dir::State::Lists=$work/lists" -o "Dir::Cache::Archives=$work/archives"
          -o "APT::Sandbox::User=root" -qq)
apt-get "${apt_opts[@]}" update >&2
( cd "$work/src" && apt-get "${apt_opts[@]}" source --download-only --tar-only swi-prolog >&2 )
orig=$(ls "$work"/src/swi-prolog_*.orig.tar.* | head -n 1)
[ -n "$orig" ] || die "apt-get source did not fetch an upstream tarball"
version=$(basename "$orig" | sed 's/^swi-prolog_\([0-9.]*\).*/\1/')
log "source: $(basename "$orig") (SWI-Prolog $version)"
tar -xf "$orig" -C "$work/src"
srcdir=$(find "$work/src" -mindepth 1 -maxdepth 1 -type d | head -n 1)

prefix="$CACHE/swipl-$version"
mkdir -p "$CACHE"
cmake -S "$srcdir" -B "$work/build" -G Ninja \
    -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX="$prefix" \
    -DSWIPL_PACKAGES_X=OFF -DSWIPL_PACKAGES_JAVA=OFF -DSWIPL_PACKAGES_ODBC=OFF \
    -DSWIPL_PACKAGES_BDB=OFF -DINSTALL_DOCUMENTATION=OFF -DBUILD_TESTING=OFF \
    -DSWIPL_PACKAGES_PYTHON=ON -DPython_EXECUTABLE="$(command -v python3)" >&2
ninja -C "$work/build" >&2
rm -rf "$prefix.tmp"
DESTDIR="" cmake --install "$work/build" >&2
[ -x "$prefix/bin/swipl" ] || die "build finished but $prefix/bin/swipl is missing"
log "installed SWI-Prolog $version in $prefix"
echo "$prefix/bin/swipl"
