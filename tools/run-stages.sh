#!/usr/bin/env bash
# Run make targets one after the other, each one's time printed as it ends and all at the end;
# from one of them on, run another target beside them and wait for it at the end.
#
# Usage: tools/run-stages.sh BESIDE FROM STAGE...
#   BESIDE  a make target run in the background once stage FROM starts (its output is
#           shown at the end), e.g. check-lab, which fills the core the builds leave idle
#   FROM    the stage from whose start BESIDE runs
#   STAGE   the make targets to run in order; the first that fails ends the run
# MAKE (the make to call) is read from the environment, as make exports it.
set -uo pipefail
beside=$1 from=$2
shift 2
make_cmd=${MAKE:-make}
beside_log=$(mktemp)
beside_pid=
status=0
times=()
for stage in "$@"; do
  if [[ $stage == "$from" ]]; then
    {
      start=$SECONDS
      $make_cmd --no-print-directory "$beside" >"$beside_log" 2>&1
      s=$?
      echo "make test: $beside took $((SECONDS - start)) s" >>"$beside_log"
      exit $s
    } &
    beside_pid=$!
  fi
  start=$SECONDS
  if ! $make_cmd --no-print-directory "$stage"; then
    status=1
    break
  fi
  times+=("$stage $((SECONDS - start)) s")
  echo "make test: $stage took $((SECONDS - start)) s"
done
if [[ -n $beside_pid ]]; then
  wait "$beside_pid" || status=1
  cat "$beside_log"
fi
rm -f "$beside_log"
if [[ $status != 0 ]]; then
  echo "make test: failed" >&2
  exit 1
fi
echo "make test: passed ($(IFS=,; echo "${times[*]}" | sed 's/,/, /g'); $beside beside from $from on)"
