#!/usr/bin/env bash
# aberrant bench on an NVIDIA machine: GLSL through EGL on the NVIDIA driver, OpenCL through the NVIDIA ICD.
#
#   scripts/bench_gpu.sh prepare      where packages can be fetched: the EGL/GL loader .debs into .gl/ and the
#                                     Python wheels the bench needs (CPython 3.12, manylinux x86-64) into .whl/
#   scripts/bench_gpu.sh run [OUT]    on the NVIDIA machine (make bench-gpu): OUT defaults to docs/bench/gpu
#
# `run` unpacks .gl/*.deb over / when the GL loaders are missing (the NVIDIA driver ships the vendor
# libraries, not libglvnd's dispatchers), installs .whl/*.whl into a scratch folder when a module is missing,
# points EGL at the NVIDIA vendor file and the OpenCL loader at libnvidia-opencl, and checks that GLSL renders
# on an NVIDIA renderer and OpenCL on an NVIDIA device. Anything missing stops it with one line saying what
# and how to get it; no NVIDIA OpenCL drops only the OpenCL backend (said in the log). Then two runs:
#
#   OUT/800x800/    every demo, the bench, architecture, hotel and overhead scenes, and the space-count sweep
#                   (N = 0, 16, 256 and 1,024 portals; boxes to 256: the float64 reference and the host's box
#                   clearances are quadratic in boxes); report.md, results.json, speed_vs_error.png, space_count.png
#   OUT/1920x1080/  every demo, the bench, architecture, hotel and overhead scenes; report, results, plot
#
# plus OUT/bench_gpu.log: eight files, what a device machine's $OUT brings back. Each run renders its
# reference frames first on every core (--jobs) and gets an equal share of what is left of BUDGET_S seconds
# (default 420, so that with the machine's start the whole stays under 9 minutes): the scenes it has not
# begun by then are skipped (--time-limit; the report lists them), and it still writes its report.
#
# Environment: GL_DIR and WHEEL_DIR (the staged .debs and wheels: .gl, .whl),
# PYTHON (default: .venv/bin/python if present, else python3), BUDGET_S, REPEAT (timed frames
# per cell, default 5), SWEEPS (default none: base settings, f32; "precision" adds f64), SIZES (default
# "800x800 1920x1080"), SCENES_800 / SCENES_1080 (override the scene lists).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

GL_DIR="${GL_DIR:-.gl}"
WHEEL_DIR="${WHEEL_DIR:-.whl}"
GL_DEBS=(libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
# The bench's imports beyond what the machine's Python brings (numpy, pillow, matplotlib), with pyproject's bounds.
WHEELS=("esper>=3.8,<4" "trimesh>=4,<6" "moderngl>=5.10,<6" "glcontext>=3,<4" "pyopencl>=2024.1" pytools
        platformdirs siphash24 "embreex>=4.4,<5")
MODULES=(esper trimesh moderngl glcontext pyopencl embreex matplotlib PIL numpy)
NVIDIA_DIRS=(/usr/local/nvidia/lib64 /usr/local/nvidia/lib /usr/lib/x86_64-linux-gnu /usr/lib64)
EGL_VENDOR=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
SPACE_SCENES="space-0"
for n in 16 256 1024; do
  for where in out in; do
    SPACE_SCENES+=" space-portals-$where-$n"
    [ "$n" -le 256 ] && SPACE_SCENES+=" space-boxes-$where-$n"
  done
done
COMMON_SCENES="demos bench architecture hotel overhead"
SCENES_800="${SCENES_800:-$COMMON_SCENES $SPACE_SCENES}"
SCENES_1080="${SCENES_1080:-$COMMON_SCENES}"

die() {
  echo "bench_gpu: error: $*" >&2
  exit 2
}

say() {
  echo "==> bench_gpu: $*"
}

prepare() {
  command -v apt-get >/dev/null || die "prepare needs apt-get (Debian or Ubuntu) to download ${GL_DEBS[*]}"
  local py="${PYTHON:-python3}"
  "$py" -m pip --version >/dev/null 2>&1 || die "prepare needs pip ($py -m pip)"
  mkdir -p "$GL_DIR" "$WHEEL_DIR" /tmp/amd64/partial
  local apt=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64)
  say "downloading ${GL_DEBS[*]} into $GL_DIR/"
  apt-get "${apt[@]}" -q update >/dev/null
  (cd "$GL_DIR" && apt-get "${apt[@]}" -q download "${GL_DEBS[@]}")
  say "downloading wheels for CPython 3.12 into $WHEEL_DIR/"
  rm -f "$WHEEL_DIR"/*.whl
  "$py" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 --platform manylinux1_x86_64 --platform manylinux_2_5_x86_64 \
    -d "$WHEEL_DIR" "${WHEELS[@]}"
  du -sh "$GL_DIR" "$WHEEL_DIR"
  say "done; on the NVIDIA machine carry .gl and .whl and run: scripts/bench_gpu.sh run \"\$OUT\""
}

find_lib() {  # the first folder holding $1 (ldconfig's cache first)
  local hit
  hit="$(ldconfig -p 2>/dev/null | awk -v lib="$1" '$1 == lib {print $NF; exit}')"
  if [ -n "$hit" ]; then
    echo "$hit"
    return 0
  fi
  local dir
  for dir in "${NVIDIA_DIRS[@]}"; do
    if [ -e "$dir/$1" ]; then
      echo "$dir/$1"
      return 0
    fi
  done
  return 1
}

setup_loaders() {
  command -v nvidia-smi >/dev/null || die "no nvidia-smi: this is not an NVIDIA machine (or its driver is not mounted)"
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader ||
    die "nvidia-smi sees no GPU"
  local dir
  for dir in "${NVIDIA_DIRS[@]:0:2}"; do
    [ -d "$dir" ] && export LD_LIBRARY_PATH="$dir${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  done
  if ! find_lib libEGL.so.1 >/dev/null || ! find_lib libGL.so.1 >/dev/null; then
    compgen -G "$GL_DIR/*.deb" >/dev/null ||
      die "no libEGL.so.1/libGL.so.1 and no $GL_DIR/*.deb to bring them: run 'scripts/bench_gpu.sh prepare' where apt works, and carry $GL_DIR"
    say "unpacking the GL loaders from $GL_DIR/"
    local deb
    for deb in "$GL_DIR"/*.deb; do dpkg -x "$deb" /; done
    ldconfig
  fi
  find_lib libEGL_nvidia.so.0 >/dev/null || die "no libEGL_nvidia.so.0: the driver's graphics libraries are not mounted"
  if [ -z "${__EGL_VENDOR_LIBRARY_FILENAMES:-}" ] && [ -e "$EGL_VENDOR" ]; then
    export __EGL_VENDOR_LIBRARY_FILENAMES="$EGL_VENDOR"
  fi
  local icd
  if icd="$(find_lib libnvidia-opencl.so.1)"; then
    if [ -z "${OCL_ICD_VENDORS:-}" ] && ! grep -qs nvidia /etc/OpenCL/vendors/*.icd; then
      mkdir -p /tmp/bench_gpu_icd
      echo "$icd" >/tmp/bench_gpu_icd/nvidia.icd
      export OCL_ICD_VENDORS=/tmp/bench_gpu_icd
    fi
  else
    say "no libnvidia-opencl.so.1: OpenCL is left out"
    NO_OPENCL=1
  fi
}

setup_python() {
  if [ -z "${PYTHON:-}" ]; then
    PYTHON=python3
    [ -x .venv/bin/python ] && PYTHON=.venv/bin/python
  fi
  command -v "$PYTHON" >/dev/null || die "no Python ($PYTHON); set PYTHON"
  "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' || die "$PYTHON is older than 3.11"
  local missing
  missing="$("$PYTHON" - "${MODULES[@]}" <<'EOF'
import importlib.util, sys
print(" ".join(m for m in sys.argv[1:] if importlib.util.find_spec(m) is None))
EOF
)"
  if [ -n "$missing" ]; then
    compgen -G "$WHEEL_DIR/*.whl" >/dev/null ||
      die "missing Python modules ($missing) and no $WHEEL_DIR/ to install them from: run 'scripts/bench_gpu.sh prepare' and carry $WHEEL_DIR"
    say "installing $WHEEL_DIR/ into /tmp/bench_gpu_site (missing: $missing)"
    "$PYTHON" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
      --target /tmp/bench_gpu_site "$WHEEL_DIR"/*.whl
    export PYTHONPATH="/tmp/bench_gpu_site${PYTHONPATH:+:$PYTHONPATH}"
    missing="$("$PYTHON" - "${MODULES[@]}" <<'EOF'
import importlib.util, sys
print(" ".join(m for m in sys.argv[1:] if importlib.util.find_spec(m) is None))
EOF
)"
    [ -z "$missing" ] || die "still missing after installing $WHEEL_DIR/: $missing"
  fi
}

check_backends() {  # prints the backends to bench; dies unless GLSL renders on the NVIDIA driver
  "$PYTHON" - "${NO_OPENCL:-0}" <<'EOF'
import sys

from backends.base import backend_class

chosen = []
for name in ("glsl", "opencl"):
    if name == "opencl" and sys.argv[1] == "1":
        continue
    reason = backend_class(name).probe()
    if reason is None:
        with backend_class(name)() as backend:
            info = backend.info()
        device = str(info.get("renderer") or info.get("device") or "")
        reason = None if "nvidia" in (device + str(info.get("platform", ""))).lower() else f"runs on {device!r}"
    print(f"{name}: {'NVIDIA: ' + device if reason is None else reason}", file=sys.stderr)
    if reason is None:
        chosen.append(name)
    elif name == "glsl":
        sys.exit(f"bench_gpu: error: GLSL does not render on the NVIDIA driver ({reason})")
print(" ".join(chosen))
EOF
}

run() {  # everything it prints also goes to OUT/bench_gpu.log
  local out="${1:-docs/bench/gpu}"
  mkdir -p "$out"
  set +e
  measure "$out" 2>&1 | tee "$out/bench_gpu.log"
  local status="${PIPESTATUS[0]}"
  set -e
  return "$status"
}

measure() {
  set -euo pipefail
  local out="$1" start budget sizes repeat
  start="$(date +%s)"
  budget="${BUDGET_S:-420}"
  sizes="${SIZES:-800x800 1920x1080}"
  repeat="${REPEAT:-5}"
  say "$(date -u '+%Y-%m-%d %H:%M:%S') UTC, budget ${budget}s, sizes: $sizes"
  setup_loaders
  setup_python
  export ABERRANT_CACHE_DIR="${ABERRANT_CACHE_DIR:-$root/.cache/aberrant}" PYTHONUNBUFFERED=1
  local backends
  backends="$(check_backends)" || exit 2
  say "backends: $backends"
  local jobs size scenes left share status=0 runs=0 done_runs=0
  jobs="$(nproc)"
  for size in $sizes; do runs=$((runs + 1)); done
  for size in $sizes; do
    scenes="$SCENES_1080"
    [ "$size" = 800x800 ] && scenes="$SCENES_800"
    left=$((budget - ($(date +%s) - start)))
    share=$((left / (runs - done_runs)))
    done_runs=$((done_runs + 1))
    if [ "$share" -lt 60 ]; then
      say "skipping $size: ${left}s of the budget left"
      status=1
      continue
    fi
    say "bench at $size (${share}s of ${left}s left): $scenes"
    local overhead=()
    [ "$size" = "${sizes%% *}" ] || overhead=(--no-overhead)  # the engine's tick does not depend on the size
    # --time-limit skips the scenes not begun by then and still writes the report; timeout is the backstop
    # for a scene that hangs. The scene and backend lists are meant to split into words.
    # shellcheck disable=SC2086
    if ! timeout --signal=INT --kill-after=20 $((share + 90)) "$PYTHON" -m aberrant bench --scenes $scenes \
        --backends $backends --size "$size" --repeat "$repeat" --sweeps "${SWEEPS:-none}" --jobs "$jobs" \
        --time-limit "$share" "${overhead[@]}" --out "$out/$size"; then
      say "the $size run failed or was stopped: see above; the runs before it stand"
      status=1
    fi
  done
  say "done in $(($(date +%s) - start))s: $out"
  return "$status"
}

# Sourced (the tests do), it only defines the functions.
if [ "${BASH_SOURCE[0]}" = "$0" ]; then
  case "${1:-}" in
    prepare) prepare ;;
    run) shift; run "$@" ;;
    *) die "usage: scripts/bench_gpu.sh prepare | run [OUT]" ;;
  esac
fi
