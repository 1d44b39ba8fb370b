#!/usr/bin/env bash
# A long run of the loaders' fuzz test (tests/fuzz.rs; the suite runs 400 cases):
#   tools/fuzz_loaders.sh [CASES]          default 20000
#   tools/fuzz_loaders.sh --seconds S      as many cases as S seconds allow (3600: an hour)
# It prints the cases tried per file (loader), the rejections and the findings. Findings are
# kept under target/tmp/fuzz_loaders/findingN and listed by the failing test.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "--seconds" ]; then
  export LIDARSIM_FUZZ_SECONDS="${2:?--seconds needs a number}"
else
  export LIDARSIM_FUZZ_CASES="${1:-20000}"
fi
exec cargo test --release --test fuzz -- --nocapture
