#!/usr/bin/env bash
# Install gpucompgen into .venv with the given extras (default: pocl), then make sure some
# OpenCL device compiles kernels. The quick start's two commands begin with this script.
#
#   bash scripts/install.sh pocl         # the demo
#   bash scripts/install.sh pocl,test    # the tests
#
# Either installs Graphviz (for 'gpucompgen graph -o x.svg', which the README's tour runs)
# where apt-get is available.
#
# PyPI's PoCL (the 'pocl' extra) cannot compile for a CPU its LLVM does not know (the
# build fails with "unknown target CPU 'generic'"); where that happens and apt-get is
# available, the distribution's PoCL (pocl-opencl-icd) is installed beside it and the
# generated programs pick whichever device compiles ('gpucompgen devices' shows which).
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-pocl}"

python3 -m venv .venv
.venv/bin/pip install -q -e ".[${extras}]"

apt_install() {
    local sudo=""
    if ! command -v apt-get >/dev/null 2>&1; then return 1; fi
    if [ "$(id -u)" != 0 ]; then
        command -v sudo >/dev/null 2>&1 || return 1
        sudo="sudo"
    fi
    export DEBIAN_FRONTEND=noninteractive
    $sudo apt-get install -y -q "$@" >/dev/null 2>&1 \
        || { $sudo apt-get update -q >/dev/null && $sudo apt-get install -y -q "$@" >/dev/null; }
}

if ! .venv/bin/gpucompgen devices --quiet; then
    echo "install.sh: no OpenCL device compiles kernels; installing the distribution's PoCL" >&2
    apt_install pocl-opencl-icd ocl-icd-libopencl1 \
        || echo "install.sh: could not install pocl-opencl-icd (no apt-get or no root)" >&2
fi
# Print the devices; fails (exit 1) with the reason when none is usable.
.venv/bin/gpucompgen devices

# Graphviz's dot draws 'gpucompgen graph' output as svg/png: the README's tour draws
# docs/vision_system.svg, and with CI=true the svg/png graph tests fail without it.
if ! command -v dot >/dev/null 2>&1; then
    apt_install graphviz \
        || echo "install.sh: no Graphviz: 'gpucompgen graph -o x.svg' (and its tests) need it; .dot works without" >&2
fi
