#!/usr/bin/env bash
# Run the packages' tests with colcon and report "N passed, M failed[, K skipped]".
# Expects the workspace set up and sourced (helio.sh does that).
#
#   test.sh                         every package
#   test.sh helio_optics [...]      only these packages
#   test.sh -- --pytest-args -k x   arguments after -- go to `colcon test`
# HELIO_TEST_TIMEOUT (s, default 1500) bounds the whole colcon test run.
# Exit status: 0 only when at least one test ran and none failed or errored.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

packages=()
while [ $# -gt 0 ] && [ "$1" != -- ]; do packages+=("$1"); shift; done
[ "${1:-}" = -- ] && shift
if [ ${#packages[@]} -eq 0 ]; then
    mapfile -t packages < <(colcon list --names-only)
fi

# A private DDS domain for this run, so tests never hear another graph on this machine.
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 100) + 100 ))}"

status=0
report="$(mktemp)"
trap 'rm -f "$report"' EXIT
(
    flock 9   # one colcon test at a time in this checkout
    for package in "${packages[@]}"; do
        rm -rf "build/$package/test_results" "build/$package/pytest.xml" \
            "build/$package/Testing"
    done
    # A hung test fails the run instead of holding CI until its own limit.
    timeout --kill-after=30 "${HELIO_TEST_TIMEOUT:-1500}" \
        colcon test --event-handlers console_cohesion+ summary+ \
        --packages-select "${packages[@]}" --pytest-args -p no:cacheprovider "$@" || {
            code=$?
            [ "$code" -ge 124 ] && echo "error: colcon test stopped after" \
                "${HELIO_TEST_TIMEOUT:-1500} s (HELIO_TEST_TIMEOUT)" >&2
            exit 1
        }
) 9>"$root/.helio.lock" || status=$?

for package in "${packages[@]}"; do
    [ -d "build/$package" ] || continue
    colcon test-result --verbose --all --test-result-base "build/$package" 2>&1 \
        | tee -a "$report" >&2 || true
done

read -r total errors failures skipped < <(python3 - "$report" <<'PYEOF'
import re
import sys
totals = [0, 0, 0, 0]
for line in open(sys.argv[1]):
    if line.startswith('Summary:'):
        for i, word in enumerate(('tests?', 'errors?', 'failures?', 'skipped')):
            match = re.search(r'(\d+) ' + word, line)
            totals[i] += int(match.group(1)) if match else 0
print(*totals)
PYEOF
)
failed=$((errors + failures))
passed=$((total - failed - skipped))
line="$passed passed, $failed failed"
[ "$skipped" -gt 0 ] && line="$line, $skipped skipped"

if [ "$total" -eq 0 ]; then
    echo "error: no test ran" >&2
    status=1
elif [ "$failed" -gt 0 ]; then
    status=1
fi
echo "$line"
exit "$status"
