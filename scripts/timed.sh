#!/usr/bin/env bash
# Run a command and print its wall-clock time at the end, whatever its exit status:
#   scripts/timed.sh LABEL COMMAND [ARG...]
set -u
label=$1; shift
start=$(date +%s)
"$@"; status=$?
elapsed=$(( $(date +%s) - start ))
printf '%s: %s after %dm %02ds\n' "$label" "$([ $status -eq 0 ] && echo passed || echo FAILED)" \
  $(( elapsed / 60 )) $(( elapsed % 60 ))
exit $status
