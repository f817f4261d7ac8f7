#!/usr/bin/env bash
# The main job: the most complete thing the workspace can run today.
# Expects the workspace set up and sourced (helio.sh does that).
#
# Today (foundation): start a PaintPattern action server and send it a goal over Fast DDS,
# printing the feedback and result. The simulated painting replaces this when it lands.
set -euo pipefail
exec python3 -m helio_control.demo "$@"
