#!/usr/bin/env bash
# Peak memory against campaign length: the same discrete-return ALS campaign over the
# bundled plane, 1 ray per pulse, at two lengths, each run whole (plan, simulate,
# products, report) under /usr/bin/time -v. Prints pulses, wall time and peak RSS per run,
# and the ratio of the peaks.
#   usage: tools/memory_scaling.sh [BINARY] [OUT_DIR] [SMALL_STEP_M] [LARGE_STEP_M]
# The along-track steps set the lengths: 0.48 m gives 100,368 pulses, 0.0048 m 10,044,672
# (492 pulses per scan line, 98 m of line).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
bin="${1:-$here/target/release/lidarsim}"
out="${2:-$here/runs/memory}"
steps=("${3:-0.48}" "${4:-0.0048}")
if [ ! -x /usr/bin/time ]; then
  echo "memory_scaling: /usr/bin/time is missing (apt-get install time)" >&2
  exit 2
fi
mkdir -p "$out"
peaks=()
for step in "${steps[@]}"; do
  camp="$out/als_plane_$step.yaml"
  cat >"$camp" <<YAML
name: als_plane_$step
scene: $here/scenes/plane.yaml
seed: 3
wavelength_nm: 1064
instrument:
  kind: discrete_return
  pulse_energy_j: 0.001
  pulse_fwhm_ns: 3.0
  footprint_half_angle_mrad: 0.25
  fov_half_angle_mrad: 0.375
  receiver_area_m2: 0.1
  bin_ns: 0.067
  max_returns: 4
platform:
  kind: als
  altitude_m: 250
  speed_m_s: 4.444444444444445
  prf_hz: 100000
  lines: [ { start: [1, 50], end: [99, 50] } ]
  scanner:
    pattern: line
    scan_angle_deg: [-11.0894, 11.0894]
    look_angle_step_deg: 0.045
    along_track_step_m: $step
simulation:
  method: bdpt
  rays_per_pulse: 1
YAML
  run="$out/run_$step"
  rm -rf "$run"
  /usr/bin/time -v "$bin" run "$camp" --out "$run" --threads 2 2>"$out/time_$step.txt" >/dev/null || {
    cat "$out/time_$step.txt" >&2
    exit 1
  }
  pulses=$(grep -o '"pulses": [0-9]*' "$run/products.json" | head -1 | grep -o '[0-9]*$')
  peak=$(awk -F': ' '/Maximum resident set size/ {print $2}' "$out/time_$step.txt")
  wall=$(awk -F': ' '/Elapsed \(wall clock\)/ {print $2}' "$out/time_$step.txt")
  echo "along_track_step_m $step: $pulses pulses, wall $wall, peak RSS $((peak / 1024)) MiB"
  peaks+=("$peak")
done
awk -v a="${peaks[0]}" -v b="${peaks[1]}" 'BEGIN { printf "peak RSS ratio, long/short: %.3f\n", b / a }'
