#!/usr/bin/env bash
# Installs what pedscan needs on Debian 12 (system packages, and Rust through rustup where
# cargo is missing), then either runs pedscan or its test suite.
#
#   bash tools/setup.sh generate [flags...]   # install, build, run `pedscan generate`
#   bash tools/setup.sh test                  # install, build, run the whole test suite
#   bash tools/setup.sh test-latest           # the Python tests with the newest PyPI releases
#   bash tools/setup.sh <any pedscan subcommand and flags>
set -euo pipefail
cd "$(dirname "$0")/.."

sudo=""
if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
packages="build-essential ca-certificates curl pkg-config mesa-vulkan-drivers libvulkan1 libvulkan-dev
  vulkan-validationlayers libshaderc-dev glslang-dev spirv-tools libhdf5-dev hdf5-tools python3-venv"
# shellcheck disable=SC2086
if ! dpkg -s $packages >/dev/null 2>&1; then
  $sudo apt-get update
  # shellcheck disable=SC2086
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $packages
fi

export PATH="$HOME/.cargo/bin:$PATH"
if ! command -v cargo >/dev/null 2>&1; then
  curl --proto '=https' --tlsv1.2 -sSf https://sh.rustup.rs | sh -s -- -y --profile minimal
fi

if [ $# -eq 0 ]; then set -- generate; fi
# The Python tools in the venv $1, installed with the pip flags that follow (PyTorch, ONNX Runtime
# and matplotlib for the networks' tests; PyPI's torch wheel brings its CUDA libraries, a few GB,
# and runs on the CPU where there is no GPU). No wheel cache: it would hold those GB a second time
# on a machine that installs once. A download cut off is tried once more; a second failure names
# itself and stops the run.
python_install() {
  local venv=$1
  shift
  [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
  local try
  for try in 1 2; do
    if "$venv/bin/pip" install --quiet --disable-pip-version-check --no-cache-dir "$@" \
      -e "tools/python[test]"; then
      return 0
    fi
    echo "setup.sh: installing the Python tools into $venv failed (try $try of 2); free disk:" >&2
    df -h "$venv" >&2 || true
  done
  return 1
}
# Their tests, on sequences made by the debug pedscan.
python_tests() {
  PEDSCAN="$PWD/target/debug/pedscan" "$1/bin/python" -m pytest tools/python/tests
}

case "$1" in
  test)
    shift
    # The Python packages pinned (tools/python/constraints.txt): the suite does not move when
    # PyPI serves a new release. They download (a few GB) while cargo compiles: the one waits on
    # the network, the other on the CPU.
    python_install tools/python/.venv -c tools/python/constraints.txt &
    pip_job=$!
    # Lavapipe runs every GPU test; the validation layer is on in each of them.
    cargo test --locked "$@"
    if ! wait "$pip_job"; then
      echo "setup.sh: the Python tools did not install (above); their tests cannot run" >&2
      exit 1
    fi
    python_tests tools/python/.venv
    ;;
  test-latest)
    # The Python tests against the newest releases PyPI serves, in a venv of their own (the
    # Rust crates stay as Cargo.lock has them).
    cargo build --locked
    python_install tools/python/.venv-latest --upgrade --upgrade-strategy eager
    python_tests tools/python/.venv-latest
    ;;
  *)
    exec cargo run --locked --release --quiet -- "$@"
    ;;
esac
