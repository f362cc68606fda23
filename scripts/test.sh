#!/usr/bin/env bash
# The test command: installs what is missing, builds, and runs every test.
#   scripts/test.sh [ctest arguments...]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${HEADFORGE_BUILD_DIR:-$root/build}"
"$root/scripts/install_deps.sh"
data="${HEADFORGE_DATA:-$root/../shared/data}"
if [ ! -d "$data/video/grid" ]; then
  echo "test.sh: the shared data folder is missing ($data); put ../shared beside the repository" >&2
  exit 1
fi
"$root/scripts/build.sh"
cd "$build"
# The tests' scratch folders under the build tree, so two checkouts tested at
# once on one machine do not share /tmp/hf_*.
export TMPDIR="$build/tmp"
mkdir -p "$TMPDIR"
ctest --output-on-failure --parallel "$(nproc)" --timeout 900 "$@"
