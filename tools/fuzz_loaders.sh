#!/usr/bin/env bash
# A long run of the loaders' fuzz test (tests/fuzz.rs; the suite runs 400 cases):
#   tools/fuzz_loaders.sh [CASES]        default 20000, about a minute here
# Findings are kept under target/tmp/fuzz_loaders/findingN and listed by the failing test.
set -euo pipefail
cd "$(dirname "$0")/.."
LIDARSIM_FUZZ_CASES="${1:-20000}" exec cargo test --release --test fuzz -- --nocapture
