#!/usr/bin/env bash
# Run every package's tests with colcon and report "N passed, M failed[, K skipped]".
# Expects the workspace set up and sourced (helio.sh does that). Extra arguments go to
# `colcon test` (e.g. --packages-select helio_optics).
# Exit status: 0 only when at least one test ran and none failed or errored.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

# A private DDS domain for this run, so tests never hear another graph on this machine.
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 100) + 100 ))}"
rm -rf "$root/build"/*/test_results "$root/build"/*/pytest.xml

status=0
colcon test --event-handlers console_cohesion+ summary+ \
    --pytest-args -p no:cacheprovider "$@" || status=$?

summary="$(colcon test-result --verbose --all 2>&1 | tee /dev/stderr | grep -E '^Summary:' | tail -n 1 || true)"
# Summary: 42 tests, 0 errors, 1 failure, 3 skipped
read -r total errors failures skipped < <(python3 - "$summary" <<'EOF'
import re
import sys
text = sys.argv[1]
def count(word):
    match = re.search(r'(\d+) ' + word, text)
    return int(match.group(1)) if match else 0
print(count('tests?'), count('errors?'), count('failures?'), count('skipped'))
EOF
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
