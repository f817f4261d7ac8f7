#!/usr/bin/env bash
# The main job: a painting through the whole graph on the simulated world, ending with the
# run report (canvas.png: the burnt panel; report.html; summary.json; the MCAP recording).
# Expects the workspace set up and sourced (helio.sh does that).
#
#   demo.sh                    paint the sample word (sample:text, 45 dots at a 3 mm pitch:
#                              the ~2 mm dots stay apart, so the report measures each one)
#   demo.sh PICTURE [opts...]  paint PICTURE (a file or sample:NAME); options go to `helio paint`
#
# `helio paint` finds no painter running, so it starts the simulated graph (world, emulated
# Dobot and servo controller on pseudo-terminals, the driver, perception, sun estimator, lens
# planner and painter nodes, each its own process), sends the /paint goal, records the run
# and stops every process it started. The painter calibrates robot-world from the marker,
# estimates the sun with the sweep, plans the dots and burns them (Algorithm 1).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
[ $# -eq 0 ] && set -- sample:text --dot-radius 0.003
picture="$1"
shift
out="$root/runs/$(date -u +%Y%m%dT%H%M%SZ)"
python3 -m helio_control paint "$picture" --out "$out" --sim "$@"
echo "[helio] the burnt panel: $out/canvas.png; the report: $out/report.html"
