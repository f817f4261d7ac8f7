#!/usr/bin/env bash
# helio: set up this workspace (idempotent) and run one job.
#
#   ./helio.sh demo    set up, build, and run the main job
#   ./helio.sh test    set up, build, run every package's colcon tests, print "N passed, M failed"
#   ./helio.sh setup   set up and build only
#   ./helio.sh shell   set up, then open a shell with the workspace sourced
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# shellcheck source=scripts/setup.sh
source "$root/scripts/setup.sh"

job="${1:-demo}"
[ $# -gt 0 ] && shift
case "$job" in
    demo|test|setup|shell) ;;
    *) echo "usage: $0 {demo|test|setup|shell} [args...]" >&2; exit 2;;
esac

t0=$SECONDS
helio_setup
echo "[helio] setup done in $((SECONDS - t0)) s" >&2

case "$job" in
    demo) exec bash "$root/scripts/demo.sh" "$@";;
    test) exec bash "$root/scripts/test.sh" "$@";;
    setup) ;;
    shell)
        # `helio` on the PATH (colcon installs it for `ros2 run helio_control helio`)
        mkdir -p "$root/install/bin"
        ln -sf "$root/install/helio_control/lib/helio_control/helio" "$root/install/bin/helio"
        PATH="$root/install/bin:$PATH" exec bash --rcfile <(echo "PS1='(helio) \\w\\$ '") -i;;
esac
