#!/usr/bin/env bash
# Instructions per simulated second of a flexao run: a measure that does not drift with the
# machine (wall time on a shared VM drifts by 10-20 % between runs; docs/architecture.md "Speed").
#
#   scripts/bench_instructions.sh [alone|run|rec]     (default: alone)
#
# alone: the twin itself (no monitor, no recording); run: with the ground-truth monitor, as
# `humanoid-twin run --no-record`; rec: also recording a .rrd. Runs flexao for 4 and for 8
# simulated seconds under valgrind's callgrind (both at once, ~1 minute on 2 cores) and prints
# the difference / 4 s: the boot, the imports and the start-up cancel out.
# Needs valgrind (Debian/Ubuntu: apt install valgrind) and the package installed (pip install -e .).
set -euo pipefail
mode=${1:-alone}
case $mode in alone|run|rec) ;; *) echo "usage: $0 [alone|run|rec]" >&2; exit 2 ;; esac
command -v valgrind >/dev/null || { echo "$0: needs valgrind (apt install valgrind)" >&2; exit 2; }
py=${PYTHON:-python}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cat > "$tmp/run.py" <<PY
import sys
from pathlib import Path
from humanoid_twin.scenarios import RunOptions, run
run(RunOptions(scenario="flexao", duration=float(sys.argv[1]), progress=False,
               monitor="$mode" != "alone", out=Path("$tmp/r.rrd") if "$mode" == "rec" else None))
PY
for d in 4 8; do
  valgrind --tool=callgrind --callgrind-out-file=/dev/null "$py" "$tmp/run.py" $d 2> "$tmp/vg$d.txt" &
done
wait
ir() {   # the run's instruction count, or the run's error and exit 1
  grep -m1 "Collected" "$1" | awk '{print $4}' | grep . ||
    { echo "$0: the run under valgrind failed ($py; set PYTHON=.venv/bin/python?):" >&2; tail -5 "$1" >&2; exit 1; }
}
a=$(ir "$tmp/vg4.txt"); b=$(ir "$tmp/vg8.txt")
echo "flexao, $mode: $(awk -v a="$a" -v b="$b" 'BEGIN { printf "%.1f", (b - a) / 4e6 }') M instructions per simulated second"
