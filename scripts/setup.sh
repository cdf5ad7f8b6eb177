#!/usr/bin/env bash
# One-step set-up, run by `make setup` (and so by `make demo` and `make test`):
#   1. system prerequisites (a C compiler, Python headers and venv, Graphviz's `dot`
#      for the plan pictures) via apt-get;
#   2. a SWI-Prolog >= 9.1.12 (scripts/provision-swipl.sh: PATH, $SWIPL, the
#      per-user cache, or a build from the distribution's source package);
#   3. .venv with `pip install -e '.[dev]'`, janus-swi compiled against that SWI;
#   4. src/spar_py/_swipl.json: the SWI-Prolog home the package must start;
#   5. the planner's Prolog compiled into the .qlf cache, and a saved state of
#      SWI-Prolog with it loaded (src/spar_py/planning/qlf.py).
# Re-running it when all is in place takes a few seconds.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
log() { printf 'setup: %s\n' "$*" >&2; }
SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO=sudo

# 1. prerequisites -----------------------------------------------------------------
need=""
command -v cc >/dev/null 2>&1 || need="$need build-essential"
command -v "$PYTHON" >/dev/null 2>&1 || need="$need python3"
command -v dot >/dev/null 2>&1 || need="$need graphviz"  # lays out and draws the plan's graphs
if command -v "$PYTHON" >/dev/null 2>&1; then
    inc=$("$PYTHON" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
    [ -f "$inc/Python.h" ] || need="$need python3-dev"
    "$PYTHON" -c 'import ensurepip, venv' >/dev/null 2>&1 || need="$need python3-venv"
fi
if [ -n "$need" ]; then
    command -v apt-get >/dev/null 2>&1 || { log "error: missing$need and no apt-get; install them by hand"; exit 1; }
    log "installing:$need"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $need
fi

# 2. SWI-Prolog ----------------------------------------------------------------------
swipl=$(scripts/provision-swipl.sh)
vars=$("$swipl" --dump-runtime-variables)
home=$(printf '%s\n' "$vars" | sed -n 's/^PLBASE="\(.*\)";$/\1/p')
version=$(printf '%s\n' "$vars" | sed -n 's/^PLVERSION="\(.*\)";$/\1/p')
[ -d "$home" ] || { log "error: $swipl reports no home directory"; exit 1; }

# 3. virtual environment and packages ---------------------------------------------------
[ -x .venv/bin/python ] || { log "creating .venv"; "$PYTHON" -m venv .venv; }
stamp=.venv/.spar-setup
want="$(sha1sum pyproject.toml | cut -d' ' -f1) $home"
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    log "installing spar-py and janus-swi (against $home)"
    export PATH="$(dirname "$swipl"):$PATH"
    .venv/bin/python -m pip install -q --upgrade pip 2>&1 | grep -v '^WARNING: Location' >&2 || true
    .venv/bin/python -m pip install -q --no-cache-dir --force-reinstall --no-deps --no-binary janus-swi janus-swi 2>&1 \
        | grep -v '^WARNING: Location' >&2 || true
    .venv/bin/python -m pip install -q -e '.[dev]' 2>&1 | grep -v '^WARNING: Location' >&2 || true
    .venv/bin/python -c 'import janus_swi' 2>/dev/null || { log "error: janus-swi did not install"; exit 1; }
    # bytecode for the dependencies, which a venv can lack (the 2-core test machine's had
    # none, with PYTHONDONTWRITEBYTECODE set): without it every `spar` process (hundreds in
    # `make test`) compiles trimesh, scipy and the rest again (`spar kb check` 1.8 s of CPU, 0.7 s with)
    .venv/bin/python -m compileall -q -j 0 "$(.venv/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')" \
        >/dev/null 2>&1 || true
    echo "$want" > "$stamp"
fi

# bytecode for spar-py's own modules: pip compiled the dependencies, but an editable
# install leaves src/ to the first import, and with PYTHONDONTWRITEBYTECODE set (some CI
# images) every cold `spar plan` would compile them again (25-60 ms measured)
.venv/bin/python -m compileall -q src bench >/dev/null || true

# 4. record the SWI-Prolog home ----------------------------------------------------------
printf '{"home": "%s", "version": %s, "swipl": "%s"}\n' "$home" "$version" "$swipl" > src/spar_py/_swipl.json

# 5. the planner's Prolog compiled into one .qlf image (src/spar_py/planning/qlf.py), so the first
#    run does not pay for it; the cache is keyed by the sources' content and the SWI
#    version, so an edited .pl file is compiled again by the next run, never loaded stale;
#    then the saved state SWI-Prolog starts from (janus and the image loaded)
.venv/bin/spar cache || log "warning: could not compile the planner's .qlf (runs consult the sources)"
log "ready: SWI-Prolog $version at $home"
