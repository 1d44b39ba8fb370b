#!/usr/bin/env bash
# Compares two folders of runs (from tools/run_bundled.sh, or two run folders) file by file.
# Every file must be byte-identical, except that in manifest.json (`wall_time_s`,
# `cpu_time_s`, `peak_memory_mib`, `pulses_simulated` (the last invocation's share, which a
# resume or a shard changes), and the checksum of report.md, which holds a wall time)
# and report.md (`simulation wall time`) the lines that hold times and memory are masked
# before comparing, and
# waveforms/*.stats.csv (seconds per pulse) and *.log are not compared at all.
# Exit 0 when all compared files are identical, 1 otherwise.
set -uo pipefail
if [ $# -ne 2 ]; then
  echo "usage: $0 BEFORE_DIR AFTER_DIR" >&2
  exit 2
fi
a=$1 b=$2
timed() {
  case "$1" in
    *.stats.csv|*.log) return 0 ;;
  esac
  return 1
}
# the file with its time and memory lines masked
masked() {
  case "$1" in
    *manifest.json) sed -E 's/"(wall_time_s|cpu_time_s|peak_memory_mib|pulses_simulated)": [0-9.e+-]+/"\1": _/; s/"report.md": "[0-9a-f]+"/"report.md": _/' "$1" ;;
    *report.md) sed -E 's/^\| simulation wall time \|.*$/| simulation wall time | _ |/' "$1" ;;
    *) cat "$1" ;;
  esac
}
same_file() {
  case "$1" in
    *manifest.json|*report.md) cmp -s <(masked "$1") <(masked "$2") ;;
    *) cmp -s "$1" "$2" ;;
  esac
}
status=0 same=0 skipped=0
while IFS= read -r rel; do
  if timed "$rel"; then skipped=$((skipped + 1)); continue; fi
  if [ ! -e "$b/$rel" ]; then echo "only in $a: $rel"; status=1; continue; fi
  if same_file "$a/$rel" "$b/$rel"; then same=$((same + 1)); else echo "differs: $rel"; status=1; fi
done < <(cd "$a" && find . -type f | sed 's|^\./||' | sort)
while IFS= read -r rel; do
  timed "$rel" && continue
  [ -e "$a/$rel" ] || { echo "only in $b: $rel"; status=1; }
done < <(cd "$b" && find . -type f | sed 's|^\./||' | sort)
echo "$same files identical (time and memory lines masked in manifest.json and report.md), $skipped timing files not compared"
[ $status -eq 0 ] && echo "identical" || echo "DIFFERENT"
exit $status
