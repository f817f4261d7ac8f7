#!/usr/bin/env bash
# The main job: a simulated painting that ends with a picture of the burnt panel.
# Expects the workspace set up and sourced (helio.sh does that). Arguments go to
# helio_drivers.sim_demo (e.g. --dots 3). Output: runs/<UTC time>/canvas.png and dots.csv.
#
# Today the simulated world (sun, lens, wood, cameras, emulated Dobot and servo controller on
# pseudo-terminals) is driven through the real serial driver libraries by a compact version of
# Algorithm 1 that aims with the simulated sun (see helio_drivers/sim_demo.py). The painter
# and lens_planner nodes with the sun estimator replace that shortcut when they exist.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$root/runs/$(date -u +%Y%m%dT%H%M%SZ)"
mkdir -p "$out"
python3 -m helio_drivers.sim_demo --out "$out" "$@"
echo "[helio] the burnt panel: $out/canvas.png (charred dots: $out/dots.csv)"
