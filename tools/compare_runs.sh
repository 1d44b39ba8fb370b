#!/usr/bin/env bash
# Compares two folders of runs (from tools/run_bundled.sh, or two run folders) file by file.
# Every file must be byte-identical except those that record wall times, which are listed
# as skipped: manifest.json (wall_time_s), waveforms/*.stats.csv (seconds per pulse) and
# report.md (throughput). Exit 0 when all compared files are identical, 1 otherwise.
set -uo pipefail
if [ $# -ne 2 ]; then
  echo "usage: $0 BEFORE_DIR AFTER_DIR" >&2
  exit 2
fi
a=$1 b=$2
timed() {
  case "$1" in
    */manifest.json|manifest.json|*.stats.csv|*/report.md|report.md|*.log) return 0 ;;
  esac
  return 1
}
status=0 same=0 skipped=0
while IFS= read -r rel; do
  if timed "$rel"; then skipped=$((skipped + 1)); continue; fi
  if [ ! -e "$b/$rel" ]; then echo "only in $a: $rel"; status=1; continue; fi
  if cmp -s "$a/$rel" "$b/$rel"; then same=$((same + 1)); else echo "differs: $rel"; status=1; fi
done < <(cd "$a" && find . -type f | sed 's|^\./||' | sort)
while IFS= read -r rel; do
  timed "$rel" && continue
  [ -e "$a/$rel" ] || { echo "only in $b: $rel"; status=1; }
done < <(cd "$b" && find . -type f | sed 's|^\./||' | sort)
echo "$same files identical, $skipped files with wall times not compared"
[ $status -eq 0 ] && echo "identical" || echo "DIFFERENT"
exit $status
