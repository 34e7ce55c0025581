#!/usr/bin/env bash
# Install what hpcwedge needs, once; a second run only checks a stamp (< 1 s).
#
#   scripts/setup.sh            core: Open MPI, PETSc (system), SLURM (for the job tests), .venv, petsc4py, package
#   scripts/setup.sh bench      also the benchmark peers (pycddlib on libcdd/libgmp)
#   scripts/setup.sh docs       also the documentation tools (MkDocs, Material, mkdocstrings)
#
# Versions: pip installs the tested versions of constraints.txt (pip install -c). For the
# newest versions setup.cfg allows instead: HPCWEDGE_CONSTRAINTS=none scripts/setup.sh
# (or make setup); HPCWEDGE_CONSTRAINTS=FILE uses another constraints file (relative to
# the repository). The stamp covers the constraints, so changing them reinstalls.
#
# Cluster path: if PETSC_DIR (and optionally PETSC_ARCH) is set, or petsc4py
# already imports in the chosen Python, that PETSc is used and no system PETSc
# is installed.  PYTHON selects the interpreter used to create .venv.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
VENV=${VENV:-$ROOT/.venv}
PY=${PYTHON:-python3}
EXTRA=${1:-core}
PETSC4PY_VERSION=3.18.5
CONSTRAINTS=${HPCWEDGE_CONSTRAINTS:-constraints.txt}
if [ "$CONSTRAINTS" = none ]; then
  PIN=(--upgrade --upgrade-strategy eager)       # the newest that setup.cfg allows
else
  [ -f "$CONSTRAINTS" ] || { echo "[setup] error: HPCWEDGE_CONSTRAINTS: no file $CONSTRAINTS (or: none)" >&2; exit 2; }
  PIN=(-c "$CONSTRAINTS")
fi
STAMP_SRC=$( { cat setup.cfg scripts/setup.sh; echo "constraints: $CONSTRAINTS";
               [ "$CONSTRAINTS" = none ] || cat "$CONSTRAINTS"; } | sha1sum | cut -c1-12)
STAMP=$VENV/.hpcwedge-$EXTRA-$STAMP_SRC

if [ -f "$STAMP" ]; then exit 0; fi
log() { echo "[setup] $*" >&2; }

apt_install() {
  local missing=()
  for p in "$@"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
  [ ${#missing[@]} -eq 0 ] && return 0
  if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then
    log "missing system packages: ${missing[*]} (not root or no apt-get: install them yourself)"; return 1
  fi
  log "apt-get install ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq >/dev/null
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}

have_petsc4py() { "$1" -c "import petsc4py; petsc4py.init(); from petsc4py import PETSc" >/dev/null 2>&1; }

SYSTEM_PETSC=1
if [ -n "${PETSC_DIR:-}" ] || have_petsc4py "$PY"; then SYSTEM_PETSC=0; fi

if command -v apt-get >/dev/null; then
  apt_install openmpi-bin libopenmpi-dev make gcc g++ gfortran pkg-config
  [ $SYSTEM_PETSC = 1 ] && apt_install petsc-dev
  # tests/test_jobs.py runs jobs/wedge.sbatch on a one-node SLURM it starts itself
  # (no service is configured or started here; auth/none, so munge stays idle).
  apt_install slurmctld slurmd slurm-client || log "SLURM not installed: the SLURM job tests will skip"
  [ "$EXTRA" = bench ] && apt_install libcdd-dev libgmp-dev
fi

if [ ! -x "$VENV/bin/python" ]; then
  log "creating $VENV"
  if have_petsc4py "$PY" && [ -z "${PETSC_DIR:-}" ]; then
    "$PY" -m venv --system-site-packages "$VENV"   # reuse the petsc4py that imports
  else
    "$PY" -m venv "$VENV"
  fi
fi
VPY=$VENV/bin/python
"$VPY" -m pip install -q "${PIN[@]}" --upgrade pip "setuptools>=64,<70" wheel   # petsc4py 3.18 does not link with newer distutils
"$VPY" -m pip install -q "${PIN[@]}" "numpy>=1.24" "cython>=3" mpi4py

if ! have_petsc4py "$VPY"; then
  if [ -z "${PETSC_DIR:-}" ]; then
    PETSC_DIR=$(ls -d /usr/lib/petscdir/petsc3.*/x86_64-linux-gnu-real 2>/dev/null | head -n1 || true)
    [ -n "$PETSC_DIR" ] || PETSC_DIR=$(readlink -f /usr/lib/petsc)
    export PETSC_ARCH=""
  fi
  export PETSC_DIR
  ver=$(sed -n 's/^#define PETSC_VERSION_\(MAJOR\|MINOR\|SUBMINOR\) *\([0-9]*\)/\2/p' "$PETSC_DIR/include/petscversion.h" | paste -sd.)
  case "$ver" in 3.18.*) want=$PETSC4PY_VERSION ;; *) want="$(echo "$ver" | cut -d. -f1,2).*" ;; esac
  log "building petsc4py==$want against PETSc $ver at $PETSC_DIR (a few minutes, once)"
  "$VPY" -m pip install -q "${PIN[@]}" --no-build-isolation "petsc4py==$want"
fi

if [ "$EXTRA" = bench ]; then
  "$VPY" -m pip install -q "${PIN[@]}" -e ".[test,bench]"
elif [ "$EXTRA" = docs ]; then
  "$VPY" -m pip install -q "${PIN[@]}" -e ".[test,docs]"
else
  "$VPY" -m pip install -q "${PIN[@]}" -e ".[test]"
fi
have_petsc4py "$VPY" || { log "petsc4py does not import"; exit 1; }
rm -f "$VENV"/.hpcwedge-"$EXTRA"-*
touch "$STAMP"
log "ready: $VENV"
