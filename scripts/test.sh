#!/usr/bin/env bash
# Run the packages' tests with colcon, then the system tests of test/ (they cross packages)
# with pytest, and report "N passed, M failed[, K skipped]" over both.
# Expects the workspace set up and sourced (helio.sh does that).
#
#   test.sh                         every package, then test/
#   test.sh helio_optics [...]      only these packages (add "system" for test/)
#   test.sh system                  only test/
#   test.sh -- --pytest-args -k x   arguments after -- go to `colcon test`
# HELIO_TEST_TIMEOUT (s, default 1500) bounds the colcon test run and the system tests each.
# HELIO_TEST_LANES (default 2): the package tests run in this many colcon runs at once, each
# in its own DDS domain (ROS_DOMAIN_ID, +1, ...) and log base (log/test_lane_N).
# HELIO_SYSTEM_LANES (default 1): the system test modules likewise, in pytest runs at once
# (domains ROS_DOMAIN_ID + 2, + 3, ...; results build/system_tests/pytest_N.xml); on 2 cores
# more lanes gain nothing (the graphs are CPU-bound).
# Exit status: 0 only when at least one test ran and none failed or errored.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

packages=()
system=0
while [ $# -gt 0 ] && [ "$1" != -- ]; do
    if [ "$1" = system ]; then system=1; else packages+=("$1"); fi
    shift
done
[ "${1:-}" = -- ] && shift
if [ ${#packages[@]} -eq 0 ] && [ "$system" -eq 0 ]; then
    mapfile -t packages < <(colcon list --names-only)
    system=1
fi

# A private DDS domain for this run, so tests never hear another graph on this machine.
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 100) + 100 ))}"

status=0
report="$(mktemp)"
trap 'rm -f "$report" "$report.stopped"' EXIT
system_results="build/system_tests"
(
    flock 9   # one test run at a time in this checkout
    for package in "${packages[@]}"; do
        rm -rf "build/$package/test_results" "build/$package/pytest.xml" \
            "build/$package/Testing"
    done
    rm -rf "$system_results"
    failed=0
    # A hung test fails the run instead of holding CI until its own limit.
    if [ ${#packages[@]} -gt 0 ]; then
        # colcon tests the packages in their build order (optics before control), one lane
        # of dependencies although no test needs another package's tests first: run them in
        # HELIO_TEST_LANES lanes instead (default 2), each colcon with its own DDS domain and
        # log base, the packages dealt out by their usual test time (scripts/test_lanes.py)
        pids=()
        lane=0
        while read -r -a lane_packages; do
            [ ${#lane_packages[@]} -gt 0 ] || continue
            (
                export ROS_DOMAIN_ID=$(( (ROS_DOMAIN_ID + lane) % 233 ))
                timeout --kill-after=30 "${HELIO_TEST_TIMEOUT:-1500}" \
                    colcon --log-base "log/test_lane_$lane" test \
                    --event-handlers console_cohesion+ summary+ \
                    --packages-select "${lane_packages[@]}" \
                    --pytest-args -p no:cacheprovider "$@" || {
                        code=$?
                        [ "$code" -ge 124 ] && echo "error: colcon test stopped after" \
                            "${HELIO_TEST_TIMEOUT:-1500} s (HELIO_TEST_TIMEOUT)" >&2 \
                            && echo "the package tests (${lane_packages[*]})" \
                            >> "$report.stopped"
                        exit 1
                    }
            ) &
            pids+=($!)
            lane=$((lane + 1))
        done < <(python3 "$root/scripts/test_lanes.py" "${HELIO_TEST_LANES:-2}" \
                 "${packages[@]}")
        for pid in "${pids[@]}"; do
            wait "$pid" || failed=1
        done
    fi
    if [ "$system" -eq 1 ]; then
        echo "[helio] system tests (test/): nodes of several packages together" >&2
        mkdir -p "$system_results"
        # HELIO_SYSTEM_LANES (default 1) pytest runs at once, each in its own DDS domain, the
        # modules dealt by their usual time; with more than one, each lane's output is
        # printed when it ends. On 2 cores two lanes gained nothing (a fresh clone: 952 and
        # 978 s against 980 s in one lane): the graphs are CPU-bound, each module took
        # 2.2-2.5x as long beside the other; on more cores they may
        pids=()
        lane=0
        lanes="${HELIO_SYSTEM_LANES:-1}"
        while read -r -a lane_files; do
            [ ${#lane_files[@]} -gt 0 ] || continue
            [ "$lanes" -gt 1 ] && echo "[helio] system lane $lane: ${lane_files[*]##*/}" >&2
            (
                export ROS_DOMAIN_ID=$(( (ROS_DOMAIN_ID + 2 + lane) % 233 ))
                log="$system_results/lane_$lane.log"
                # one lane: its output as it comes; more: each printed when it ends
                timeout --kill-after=30 "${HELIO_TEST_TIMEOUT:-1500}" \
                    python3 -m pytest "${lane_files[@]}" -p no:cacheprovider -q \
                    --junitxml="$system_results/pytest_$lane.xml" \
                    -o junit_suite_name="system_tests_$lane" 2>&1 \
                    | if [ "$lanes" -gt 1 ]; then cat > "$log"; else tee "$log" >&2; fi \
                    || {
                        code=$?
                        [ "$code" -ge 124 ] && echo "error: the system tests (lane $lane)" \
                            "stopped after ${HELIO_TEST_TIMEOUT:-1500} s" \
                            "(HELIO_TEST_TIMEOUT)" | tee -a "$log" >&2 \
                            && echo "the system tests (lane $lane)" >> "$report.stopped"
                        [ "$lanes" -gt 1 ] && echo "[helio] system lane $lane:" >&2 \
                            && cat "$log" >&2
                        exit 1
                    }
                if [ "$lanes" -gt 1 ]; then
                    echo "[helio] system lane $lane:" >&2
                    cat "$log" >&2
                fi
            ) &
            pids+=($!)
            lane=$((lane + 1))
        done < <(python3 "$root/scripts/test_lanes.py" "$lanes" \
                 "$root"/test/test_*.py)
        for pid in "${pids[@]}"; do
            wait "$pid" || failed=1
        done
    fi
    exit "$failed"
) 9>"$root/.helio.lock" || status=$?

result_dirs=()
for package in "${packages[@]}"; do
    [ -d "build/$package" ] && result_dirs+=("build/$package")
done
[ "$system" -eq 1 ] && [ -d "$system_results" ] && result_dirs+=("$system_results")
for directory in "${result_dirs[@]}"; do
    colcon test-result --verbose --all --test-result-base "$directory" 2>&1 \
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
if [ -s "$report.stopped" ]; then
    # a run cut off by HELIO_TEST_TIMEOUT wrote no results: say so in the summary line
    line="$line; stopped by the timeout, not counted: $(paste -sd, "$report.stopped")"
    status=1
fi

if [ "$total" -eq 0 ]; then
    echo "error: no test ran" >&2
    status=1
elif [ "$failed" -gt 0 ]; then
    status=1
fi
echo "$line"
exit "$status"
