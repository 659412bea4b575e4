#!/usr/bin/env bash
# Set up a fresh Debian machine for the viewer: system libraries (EGL/GL through Mesa, LLVM for
# Mitsuba's fast variant, Xvfb for window tests) and a .venv in the repository root.
#   bash .ci/setup.sh          the viewer and the reference (Mitsuba)
#   bash .ci/setup.sh test     ... plus what the tests need
set -euo pipefail
cd "$(dirname "$0")/.."

# EGL/GL through Mesa; LLVM for Mitsuba; Xvfb and the X libraries glfw loads at run time (and XTEST for
# the window tests)
packages=(libegl1 libgl1 libgles2 libllvm19 xvfb xauth libx11-6 libxext6 libxrandr2 libxinerama1
          libxcursor1 libxi6 libxtst6)
missing=()
for p in "${packages[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  elif command -v sudo >/dev/null && sudo -n true 2>/dev/null; then
    sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  else
    echo "setup: please install the system packages: sudo apt-get install ${missing[*]}" >&2
    exit 1
  fi
fi

# pip keeps no copy of what it downloads: a fresh machine installs once, and the wheels of the test
# extras (Ray, Mitsuba, onnx) would stay in its cache, on a disk that may be small
export PIP_NO_CACHE_DIR=1

python=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$python" -m venv .venv
fi
extras="reference"
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
if [ "${1:-}" = "test" ]; then
  # The tests train and export tiny networks (torch, the `train` extra) and make tiny datasets on Ray
  # (`ray`, in the `train` and `test` extras: the core package, no GPU). Pin torch's CPU build first: on
  # these machines `pip install torch==2.13.0` takes a local CPU wheel, while an unpinned torch would
  # pull the registry's newest build with several GB of CUDA packages.
  .venv/bin/python -m pip install -q "torch==2.13.0"
  extras="reference,test,train"
fi
.venv/bin/python -m pip install -q -e ".[${extras}]"

# Compile the ray kernels once now, both GI sources' (numba caches them), so that the first `python -m
# viewer` starts in seconds rather than minutes and the network's first answer takes under a second
# rather than eight.
echo "setup: compiling the ray kernels for this machine (numba caches them; about half a minute) ..." >&2
warm=$(mktemp -d)
{ .venv/bin/python -m viewer capture cornell --size 64x48 --out "$warm/warm.png" \
    && .venv/bin/python -m viewer capture cornell --size 64x48 --gi neural --out "$warm/warm.png"; } >/dev/null 2>&1 \
  || echo "setup: could not compile them now; the first run of the viewer will" >&2
rm -rf "$warm"
