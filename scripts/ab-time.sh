#!/usr/bin/env bash
# Times two builds of a command against each other on a noisy machine: the
# two run in turn (B A B A ...), each run's wall and CPU seconds from
# /usr/bin/time, then the medians and the median of the A/B ratios taken
# pair by pair (a pair shares the machine's speed of its minute).
#
#   scripts/ab-time.sh RUNS 'COMMAND_A' 'COMMAND_B'
#
# `{run}` in a command is replaced by the run's number (an output folder
# per run: `gap` refuses to write into one that exists). Example, the
# diagnosis of a foreign dataset by this head against an older build:
#
#   scripts/ab-time.sh 3 \
#     'target/release/host-sim gap fds --force --out /tmp/a{run}' \
#     '/tmp/old/host-sim gap fds --force --out /tmp/b{run}'
#
# Needs GNU time (/usr/bin/time) and awk.
set -euo pipefail
if [ "$#" -ne 3 ] || ! [[ "$1" =~ ^[1-9][0-9]*$ ]]; then
  echo "usage: $0 RUNS 'COMMAND_A' 'COMMAND_B' (RUNS a whole number from 1)" >&2
  exit 2
fi
if [ ! -x /usr/bin/time ]; then
  echo "$0: needs GNU time at /usr/bin/time" >&2
  exit 2
fi
runs=$1
log=$(mktemp)
trap 'rm -f "$log"' EXIT
one() {
  local label=$1 command=${2//\{run\}/$3}
  # shellcheck disable=SC2086 # the command is split as a shell splits words
  /usr/bin/time -f "$label %e %U %S" -a -o "$log" $command >/dev/null 2>&1 ||
    { echo "$0: '$command' failed" >&2; exit 1; }
}
for run in $(seq 1 "$runs"); do
  one B "$3" "$run"
  one A "$2" "$run"
done
awk -v runs="$runs" '
  function median(v, n,   i, j, t) {
    for (i = 1; i <= n; i++) for (j = i + 1; j <= n; j++) if (v[j] < v[i]) { t = v[i]; v[i] = v[j]; v[j] = t }
    return n % 2 ? v[(n + 1) / 2] : (v[n / 2] + v[n / 2 + 1]) / 2
  }
  $1 == "A" { na++; aw[na] = $2; ac[na] = $3 + $4 }
  $1 == "B" { nb++; bw[nb] = $2; bc[nb] = $3 + $4 }
  END {
    for (i = 1; i <= runs; i++) { rw[i] = aw[i] / bw[i]; rc[i] = bc[i] > 0 ? ac[i] / bc[i] : 1; lw = lw sprintf(" %.1f/%.1f", aw[i], bw[i]) }
    printf "wall s, A/B each pair:%s\n", lw
    printf "A: wall %.1f s, CPU %.1f s (medians of %d)\n", median(aw, runs), median(ac, runs), runs
    printf "B: wall %.1f s, CPU %.1f s\n", median(bw, runs), median(bc, runs)
    printf "A/B pair by pair: wall %.3f, CPU %.3f (medians)\n", median(rw, runs), median(rc, runs)
  }' "$log"
