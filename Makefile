# aberrant — set-up, demo, tests.
#
#   make demo    install what is missing, render the aberration tunnels: an image and a short flythrough
#   make test    install what is missing, run the test suite
#
# Set-up (shared by every target that runs code), each step skipped when done:
#   1. apt packages (Debian): the Mesa EGL/OpenGL stack for headless moderngl on
#      llvmpipe, the OpenCL ICD loader, glfw for the editor. Checked with dpkg on
#      every run (fast); apt-get runs only when something is missing.
#   2. .venv (python3.11, or python3 if it is 3.11+), pip upgraded, then
#      `pip install -e '.[dev,glsl,opencl,editor,bench,cluster]'`; stamped on pyproject.toml, so
#      editing pyproject reinstalls and nothing else does.

SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
.ONESHELL:
.DEFAULT_GOAL := help
.DELETE_ON_ERROR:

# Mesa EGL/GL for moderngl.create_standalone_context(backend="egl"):
#   libegl1          libEGL.so.1 (glvnd dispatcher)
#   libegl-mesa0     Mesa's EGL vendor library (surfaceless / device platforms)
#   libgl1           libGL.so.1, which glcontext's EGL backend also loads for GL symbols
#   libgl1-mesa-dri  the Mesa drivers, llvmpipe (software rasteriser) among them
# OpenCL: ocl-icd-libopencl1 (ICD loader) and pocl-opencl-icd (Debian's PoCL 3.1 on LLVM 15: 25-50 % less CPU per
# frame than the PyPI build of PoCL 3.0 that pyopencl[pocl] brings, which stays as the no-root fallback).
# Editor: libglfw3; xvfb for its window tests (a virtual display on a headless machine).
APT_PACKAGES := libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri ocl-icd-libopencl1 pocl-opencl-icd libglfw3 xvfb

# The interpreter the venv is made from; override with `make BASE_PYTHON=/path/to/python3.x test`.
BASE_PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3 2>/dev/null)
VENV := .venv
PY := $(VENV)/bin/python
EXTRAS := dev,glsl,opencl,editor,bench,cluster
VENV_OK := $(VENV)/.stamp-venv
INSTALLED := $(VENV)/.stamp-installed

# Extra arguments for pytest, e.g. `make test PYTEST_ARGS="-k portal -x"`.
PYTEST_ARGS ?=
# Test worker processes (pytest-xdist): one per core; 0 runs the tests in make's own pytest process.
TEST_WORKERS ?= auto
BENCH_GPU_OUT ?= docs/bench/gpu
DEMO := aberration_tunnels
DEMO_OUT := out/$(DEMO).png
DEMO_CLIP := out/$(DEMO).gif

.PHONY: help setup apt-packages demo gallery docs test bench bench-gpu bench-pytest lint format clean

help:
	@echo "aberrant — make targets:"
	echo "  make demo    install what is missing, render $(DEMO) to $(DEMO_OUT) and $(DEMO_CLIP)"
	echo "  make test    install what is missing, run the test suite (pytest -q, a worker per core)"
	echo "  make bench   speed against error report: aberrant bench --out out/bench (BENCH_ARGS=...)"
	echo "  make bench-gpu  the bench on an NVIDIA machine: scripts/bench_gpu.sh run $(BENCH_GPU_OUT)"
	echo "  make bench-pytest  the pytest-benchmark micro-benchmarks"
	echo "  make gallery render every demo into docs/gallery/ (the README's gallery)"
	echo "  make docs    the API reference from the docstrings (pdoc) into out/api/; fails on broken references"
	echo "  make lint    ruff check + ruff format --check + mypy (the packages; configured in pyproject.toml)"
	echo "  make format  ruff format + ruff check --fix"
	echo "  make setup   only install (apt packages, .venv, the package in editable mode)"
	echo "  make clean   remove .venv and caches"

setup: $(INSTALLED)

# ---------------------------------------------------------------------------
# 1. apt packages. A phony check that runs every time (a few dpkg calls); it is
#    an order-only prerequisite below so it never makes the venv look stale.
apt-packages:
	@if ! command -v dpkg >/dev/null 2>&1; then
	  echo "==> warning: no dpkg (not Debian?): make sure these are installed: $(APT_PACKAGES)" >&2
	  exit 0
	fi
	missing=()
	for p in $(APT_PACKAGES); do
	  if ! dpkg -s "$$p" 2>/dev/null | grep -q '^Status: install ok installed'; then missing+=("$$p"); fi
	done
	# Debian's own python3.x keeps venv's ensurepip in a separate package.
	if [ ! -e "$(VENV_OK)" ] && pyver=$$("$(BASE_PYTHON)" -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null) \
	    && ! "$(BASE_PYTHON)" -c 'import ensurepip' >/dev/null 2>&1; then
	  missing+=("python$$pyver-venv")
	fi
	[ $${#missing[@]} -eq 0 ] && exit 0
	cmd="apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $${missing[*]}"
	if [ "$$(id -u)" -ne 0 ]; then
	  echo "error: missing apt packages: $${missing[*]}" >&2
	  echo "       install them as root, then run make again:" >&2
	  echo "       sudo sh -c '$$cmd'" >&2
	  exit 1
	fi
	echo "==> installing apt packages: $${missing[*]}"
	apt-get update -q
	DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "$${missing[@]}"

# ---------------------------------------------------------------------------
# 2a. The virtual environment. An existing, working .venv (3.11+, with pip) is
#     kept; a missing or broken one is made afresh.
$(VENV_OK): | apt-packages
	@if [ -x "$(PY)" ] && "$(PY)" -c 'import sys; assert sys.version_info >= (3, 11)' >/dev/null 2>&1 \
	    && "$(PY)" -m pip --version >/dev/null 2>&1; then
	  touch "$@"; exit 0
	fi
	py="$(BASE_PYTHON)"
	if [ -z "$$py" ]; then
	  echo "error: no python3.11 or python3 on PATH; install Python 3.11 (Debian 12: apt-get install python3 python3-venv)" >&2
	  exit 1
	fi
	if ! ver=$$("$$py" -c 'import platform; print(platform.python_version())' 2>/dev/null); then
	  echo "error: cannot run $$py (BASE_PYTHON)" >&2
	  exit 1
	fi
	if ! "$$py" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
	  echo "error: $$py is Python $$ver; aberrant needs 3.11+" >&2
	  echo "       install python3.11, or run: make BASE_PYTHON=/path/to/python3.11 ..." >&2
	  exit 1
	fi
	echo "==> creating $(VENV) with $$py ($$ver)"
	rm -rf "$(VENV)"
	"$$py" -m venv "$(VENV)"
	touch "$@"

# 2b. pip and the package itself, editable, with all extras.
$(INSTALLED): pyproject.toml $(VENV_OK)
	@echo "==> upgrading pip in $(VENV)"
	"$(PY)" -m pip install -q --upgrade pip
	echo "==> installing aberrant (editable) with extras [$(EXTRAS)] into $(VENV)"
	"$(PY)" -m pip install -q -e '.[$(EXTRAS)]'
	touch "$@"

# ---------------------------------------------------------------------------
# Targets that use the environment. Order-only prerequisites: the apt check runs
# every time (it is cheap), the install only when its stamp is stale.
demo: | apt-packages $(INSTALLED)
	@mkdir -p "$(dir $(DEMO_OUT))"
	echo "==> rendering the $(DEMO) demo with the fastest backend here"
	"$(VENV)/bin/aberrant" render $(DEMO) --backend auto --size 800x600 --spp 4 --out "$(DEMO_OUT)"
	echo "==> rendering a flythrough (the camera path drives the real systems)"
	"$(VENV)/bin/aberrant" render $(DEMO) --backend auto --size 320x240 --path --duration 14 --fps 15 --out "$(DEMO_CLIP)"
	echo "==> image: $(abspath $(DEMO_OUT))"
	echo "==> flythrough: $(abspath $(DEMO_CLIP))"

# The README's gallery: every demo at 800x600 with 8 samples per pixel, traced by OpenCL in float64 (at
# parity with the reference, which the tests check, and minutes faster at this size).
gallery: | apt-packages $(INSTALLED)
	@for demo in $$("$(PY)" -c 'from demos import demo_names; print(" ".join(demo_names()))'); do
	  "$(VENV)/bin/aberrant" render "$$demo" --backend opencl --precision f64 --size 800x600 --spp 8 --out "docs/gallery/$$demo.png"
	done

# The API reference: HTML from every package's docstrings into out/api/ (docs/build_api.py). It fails on
# pdoc's warnings and on cross-references that would render without a link. No display: importing the
# editor's modules must not need one.
docs: | apt-packages $(INSTALLED)
	@env -u DISPLAY -u WAYLAND_DISPLAY "$(PY)" docs/build_api.py out/api

test: | apt-packages $(INSTALLED)
	@"$(PY)" -m pytest -q -n $(TEST_WORKERS) $(PYTEST_ARGS)

# Speed against error: every backend and setting on every scene -> out/bench/{report.md,results.json,speed_vs_error.png}.
bench: | apt-packages $(INSTALLED)
	@"$(VENV)/bin/aberrant" bench --out out/bench $(BENCH_ARGS)

# The bench on an NVIDIA machine: GLSL through EGL on the NVIDIA driver, OpenCL through its ICD, 800x800 and
# 1920x1080 -> $(BENCH_GPU_OUT)/<size>/. No set-up prerequisites: such a machine brings its own Python, and
# `scripts/bench_gpu.sh prepare` (run where packages can be fetched) stages the loaders and wheels it lacks.
bench-gpu:
	@scripts/bench_gpu.sh run "$(BENCH_GPU_OUT)"

# The pytest-benchmark micro-benchmarks (tests/bench_*.py).
# --benchmark-only overrides the --benchmark-skip in pyproject's addopts;
# --benchmark-enable overrides a --benchmark-disable should one be added.
bench-pytest: | apt-packages $(INSTALLED)
	@"$(PY)" -m pytest -q -rfE --benchmark-only --benchmark-enable tests/ $(PYTEST_ARGS)

lint: | apt-packages $(INSTALLED)
	@status=0
	echo "==> ruff check"
	"$(VENV)/bin/ruff" check . || status=1
	echo "==> ruff format --check"
	"$(VENV)/bin/ruff" format --check . || status=1
	echo "==> mypy"
	"$(VENV)/bin/mypy" || status=1
	exit $$status

format: | apt-packages $(INSTALLED)
	@"$(VENV)/bin/ruff" format .
	"$(VENV)/bin/ruff" check --fix .

clean:
	@echo "==> removing $(VENV), caches and build files"
	rm -rf "$(VENV)" .pytest_cache .ruff_cache .mypy_cache .cache build *.egg-info
	find . -path ./.git -prune -o -type d -name __pycache__ -print0 | xargs -0 rm -rf
