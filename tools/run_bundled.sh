#!/usr/bin/env bash
# Runs every bundled campaign (pipelines/*.yaml) with one lidarsim binary into OUT/<name>/,
# so that two builds can be compared file by file with tools/compare_runs.sh:
#   tools/run_bundled.sh target/release/lidarsim /tmp/before
#   ... change the code, build ...
#   tools/run_bundled.sh target/release/lidarsim /tmp/after
#   tools/compare_runs.sh /tmp/before /tmp/after
# Campaigns over the RAMI orchard are left out, saying so, when ../shared/data/rami-wco is absent.
# SKIP="name1 name2" leaves out campaigns by name; THREADS sets --threads (default: all cores).
set -euo pipefail
if [ $# -ne 2 ]; then
  echo "usage: $0 LIDARSIM_BINARY OUT_DIR" >&2
  exit 2
fi
bin=$(realpath "$1")
out=$2
cd "$(dirname "$0")/.."
mkdir -p "$out"
threads=()
[ -n "${THREADS:-}" ] && threads=(--threads "$THREADS")
for f in pipelines/*.yaml; do
  name=$(basename "$f" .yaml)
  case " ${SKIP:-} " in *" $name "*) echo "skip $name (SKIP)" >&2; continue ;; esac
  if grep -q "rami_wco" "$f" && [ ! -d ../shared/data/rami-wco ]; then
    echo "skip $name: ../shared/data/rami-wco is absent" >&2
    continue
  fi
  start=$(date +%s)
  "$bin" run "$f" --out "$out/$name" "${threads[@]}" >"$out/$name.log" 2>&1 \
    || { echo "FAILED $name (see $out/$name.log)" >&2; exit 1; }
  echo "ran $name in $(( $(date +%s) - start )) s" >&2
done
