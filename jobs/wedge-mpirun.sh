#!/bin/bash
# hpcwedge on a workstation (no batch system): mpirun with sensible defaults.
#
#   jobs/wedge-mpirun.sh [-n RANKS] [--no-resume] SCENE.toml [RESULT.h5]
#
#   -n RANKS      MPI ranks (default: the number of CPUs this process may use);
#                 --oversubscribe is added when RANKS exceeds the cores
#   --no-resume   start from scratch even if a checkpoint exists
#   RESULT.h5     default: SCENE's base name with .h5, in the current directory
#
# Runs `mpirun -n RANKS python -m hpcwedge run SCENE -o RESULT --resume`: a
# rerun continues from the checkpoint beside RESULT (or starts fresh when there
# is none). Ctrl-C / SIGTERM / SIGHUP: SIGTERM goes to the ranks (mpirun's
# children), not to mpirun: the master writes a checkpoint, tells the workers to
# stop (they ignore SIGTERM) and exits 75, and so does mpirun, then this script.
# (Open MPI 4's mpirun exits 1 on a SIGTERM of its own, whatever the ranks do.)
# SIGTERM to mpirun if no rank is found, SIGKILL if it is still there
# HPCWEDGE_KILL_AFTER seconds later (default 120: 64 workers oversubscribed on 2 busy
# cores took over 30 s to hand back their tasks and exit).
# mpirun runs in its own session so that the terminal's Ctrl-C reaches only this
# script (Open MPI's mpirun would answer it by killing the ranks at once).
# Send the run SIGUSR1 yourself for a checkpoint without stopping.
#
# Environment: HPCWEDGE_ROOT, HPCWEDGE_PYTHON, HPCWEDGE_MPIRUN,
# HPCWEDGE_MPIRUN_ARGS (as for jobs/wedge.sbatch), HPCWEDGE_KILL_AFTER.

log() { printf '%s [wedge-mpirun] %s\n' "$(date '+%F %T')" "$*" >&2; }
stop_sig="" stop_t=0 term_t=0 child=""
# shellcheck disable=SC2317  # called from the traps
on_signal() {
  if [ -z "$stop_sig" ]; then
    stop_sig=$1 stop_t=$SECONDS
    if [ -n "$child" ]; then
      log "signal $1 received: SIGTERM to the ranks of ${LAUNCH[0]:-mpirun} (pid $child); the master checkpoints and stops"
      term_t=$SECONDS
      stop_ranks
    else
      log "signal $1 received before the launch"
    fi
  fi
}
# The launcher's children that are ranks (OMPI_COMM_WORLD_RANK or PMIX_RANK in their environment)
local_ranks() {
  local p
  for p in $(ps -o pid= --ppid "$child" 2>/dev/null); do
    tr '\0' '\n' < "/proc/$p/environ" 2>/dev/null | grep -q -e '^OMPI_COMM_WORLD_RANK=' -e '^PMIX_RANK=' && echo "$p"
  done
}
# Whether process $1 catches or ignores SIGTERM (bit 15 of SigCgt or SigIgn in /proc/PID/status):
# hpcwedge's handlers are in, and a SIGTERM no longer kills it
takes_term() {
  local f m
  for f in SigCgt SigIgn; do
    m=$(sed -n "s/^$f:[[:space:]]*//p" "/proc/$1/status" 2>/dev/null)
    [ -n "$m" ] && (( (16#${m: -4} >> 14) & 1 )) && return 0
  done
  return 1
}
# SIGTERM to the launcher's children (the ranks on this host; rank 0 among them), or to the
# launcher when it has none. A rank still starting (not yet forked, or loading Python) would be
# killed by it, and the run with it: up to STOP_WAIT seconds, while the run lives, until all
# RANKS ranks are there and take SIGTERM (on a loaded CI machine a stop 1.6 s after the launch
# killed a rank: exit 143, no checkpoint)
STOP_WAIT=20
stop_ranks() {
  local until=$((SECONDS + STOP_WAIT)) ranks n ready p
  while kill -0 "$child" 2>/dev/null && [ "$SECONDS" -lt "$until" ]; do
    ranks=$(local_ranks) n=0 ready=1
    for p in $ranks; do
      n=$((n + 1))
      takes_term "$p" || ready=0
    done
    [ "$n" -ge "$RANKS" ] && [ "$ready" = 1 ] && break
    sleep 0.2
  done
  ranks=$(ps -o pid= --ppid "$child" 2>/dev/null)
  if [ -n "$ranks" ]; then
    # shellcheck disable=SC2086  # one pid per word
    kill -TERM $ranks 2>/dev/null
  else
    kill -TERM "$child" 2>/dev/null
  fi
}
trap 'on_signal INT' INT
trap 'on_signal TERM' TERM
trap 'on_signal HUP' HUP

set -uo pipefail
die() { log "error: $1"; exit "${2:-2}"; }
usage="usage: jobs/wedge-mpirun.sh [-n RANKS] [--no-resume] SCENE.toml [RESULT.h5]"

RANKS="" RESUME=(--resume) ARGS=()
while [ $# -gt 0 ]; do
  case "$1" in
    -n|--np) [ $# -ge 2 ] || die "$usage"; RANKS=$2; shift 2 ;;
    -n*) RANKS=${1#-n}; shift ;;
    --no-resume) RESUME=(); shift ;;
    -h|--help) sed -n '2,25s/^# \{0,1\}//p' "$0"; exit 0 ;;
    --) shift; ARGS+=("$@"); break ;;
    -*) die "unknown option $1; $usage" ;;
    *) ARGS+=("$1"); shift ;;
  esac
done
[ ${#ARGS[@]} -ge 1 ] && [ ${#ARGS[@]} -le 2 ] || die "$usage"
SCENE=${ARGS[0]}
RESULT=${ARGS[1]:-$(basename "${SCENE%.toml}").h5}
[ -r "$SCENE" ] || die "scene $SCENE: not readable"
mkdir -p "$(dirname "$RESULT")" || die "cannot create the directory of $RESULT"

CPUS=$(nproc 2>/dev/null || echo 1)
CORES=$(lscpu -p=CORE,SOCKET 2>/dev/null | grep -v '^#' | sort -u | wc -l)
[ "${CORES:-0}" -ge 1 ] && [ "$CORES" -lt "$CPUS" ] && CPUS=$CORES   # Open MPI counts cores, not threads
RANKS=${RANKS:-$CPUS}
KILL_AFTER=${HPCWEDGE_KILL_AFTER:-120}
[[ "$KILL_AFTER" =~ ^[0-9]+$ ]] || die "HPCWEDGE_KILL_AFTER=$KILL_AFTER: not a number of seconds"
[[ "$RANKS" =~ ^[1-9][0-9]*$ ]] || die "-n $RANKS: not a positive integer"

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
ROOT=${HPCWEDGE_ROOT:-}
[ -z "$ROOT" ] && [ -f "$here/hpcwedge/__init__.py" ] && ROOT=$here
if [ -n "$ROOT" ]; then
  [ -f "$ROOT/hpcwedge/__init__.py" ] || die "HPCWEDGE_ROOT=$ROOT holds no hpcwedge/ package"
  export PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}"
fi
PY=${HPCWEDGE_PYTHON:-}
if [ -z "$PY" ]; then
  if [ -n "$ROOT" ] && [ -x "$ROOT/.venv/bin/python" ]; then PY=$ROOT/.venv/bin/python; else PY=python3; fi
fi
PKG=$("$PY" -c 'import hpcwedge; print(hpcwedge.__file__)' 2>&1) \
  || die "$PY cannot import hpcwedge (set HPCWEDGE_PYTHON or HPCWEDGE_ROOT): $PKG"

read -r -a LAUNCH <<< "${HPCWEDGE_MPIRUN:-mpirun}"
command -v "${LAUNCH[0]}" >/dev/null || die "launcher ${LAUNCH[0]} not found (apt-get install openmpi-bin?)"
read -r -a EXTRA <<< "${HPCWEDGE_MPIRUN_ARGS:-}"
if [ "$RANKS" -gt "$CPUS" ]; then
  EXTRA=(--oversubscribe "${EXTRA[@]}")
fi
[ "$(id -u)" = 0 ] && export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# The ranks exit by themselves after a stop (the master first, with its checkpoint on disk);
# Open MPI 4's mpirun then waits its kill timeout twice before it exits (2 s measured)
export OMPI_MCA_odls_base_sigkill_timeout=${OMPI_MCA_odls_base_sigkill_timeout:-0}
SETSID=()
command -v setsid >/dev/null && SETSID=(setsid)

CMD=("${LAUNCH[@]}" -n "$RANKS" "${EXTRA[@]}" "$PY" -m hpcwedge run "$SCENE" -o "$RESULT" "${RESUME[@]}")
log "start: $RANKS rank(s) on $CPUS core(s); hpcwedge $PKG"
if [ -n "$stop_sig" ]; then log "stopped by SIG$stop_sig before the launch"; exit 130; fi
"${SETSID[@]}" "${CMD[@]}" < /dev/null &
child=$!
log "launch: ${CMD[*]} (mpirun pid $child)"
[ -n "$stop_sig" ] && { term_t=$SECONDS; kill -TERM "$child" 2>/dev/null; }   # before its ranks exist

while kill -0 "$child" 2>/dev/null; do
  if [ -z "$stop_sig" ]; then
    wait "$child"
  else
    if [ "$term_t" != 0 ] && [ $((SECONDS - term_t)) -ge "$KILL_AFTER" ]; then
      log "${LAUNCH[0]} still running ${KILL_AFTER} s after SIGTERM: SIGKILL"
      kill -KILL "$child" 2>/dev/null
    fi
    sleep 0.2 & wait $!
  fi
done
wait "$child"; rc=$?

complete=0
[ $rc = 0 ] && complete=$("$PY" - "$SCENE" "$RESULT" <<'PYEOF' 2>/dev/null
import sys
from hpcwedge.results.hdf5 import result_state
from hpcwedge.scene.parse import load_scene
scene, result = sys.argv[1:3]
print(int(result_state(result, load_scene(scene)) == "complete"))      # as jobs/wedge.sbatch
PYEOF
)
if [ $rc = 0 ] && [ "$complete" = 1 ]; then
  log "done: $RESULT${stop_sig:+ (completed before stopping)}"; exit 0
fi
if [ -n "$stop_sig" ]; then
  if [ $rc = 75 ]; then
    log "stopped by SIG$stop_sig, checkpoint written (exit 75); rerun the same command to resume"; exit 75
  fi
  log "stopped by SIG$stop_sig (run exit $rc); rerun the same command to resume"
  case "$stop_sig" in INT) exit 130 ;; HUP) exit 129 ;; *) exit 143 ;; esac
fi
if [ $rc = 0 ]; then log "error: the run exited 0 but $RESULT is not a complete result"; exit 1; fi
log "error: the run failed (exit $rc)"
exit $rc
