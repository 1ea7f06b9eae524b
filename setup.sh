#!/usr/bin/env bash
# Sets up everything this project needs on a fresh Debian 12 machine, then runs the main
# job on the embedded default suite.  Safe to run again: it only installs what is missing
# and rebuilds the C++ core incrementally (build/).
#
#   Debian packages  compiler, CMake, Python headers; libllvm19 for drjit's LLVM backend
#   .venv/           a virtual environment with the package installed in editable mode
#                    (this builds reference_estimators/_core with scikit-build-core + nanobind)
#   libosmesa6       headless OpenGL for pyrender;  chromium  the report tests' browser
set -euo pipefail
cd "$(dirname "$0")"

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

PACKAGES=(g++ cmake ninja-build python3 python3-venv python3-dev libllvm19 libosmesa6 chromium)
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

PYTHON="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv with $($PYTHON --version)"
  "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
echo "setup: building and installing the package (C++ core included)"
.venv/bin/python -m pip install -q -e ".[test,bench,render]"
# pyrender pins PyOpenGL==3.1.0 (no OSMesaCreateContextAttribs); its other requirements come
# with the "render" extra above, so it is installed without its pin.
.venv/bin/python -m pip install -q --no-deps "pyrender==0.1.45"
# the pytest plugin's entry point lives in a distribution of its own (see its pyproject.toml)
.venv/bin/python -m pip install -q --no-deps ./plugins/pytest-harness

echo "setup: running the main job: harness run suites/default.toml"
status=0
.venv/bin/harness run suites/default.toml || status=$?
# the report is written even when a check failed: that is when it is needed
.venv/bin/harness report --db results/default.sqlite -o results/default.html
echo "setup: report of the main job: $(pwd)/results/default.html (open it in a browser)"
exit $status
