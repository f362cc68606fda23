#!/usr/bin/env bash
# The test command: installs what is missing, builds, and runs the tests.
#   scripts/test.sh [--figures] [ctest arguments...]
# Without --figures the tests labelled "figure" (an accuracy figure measured
# on a benchmark's input, minutes each) are left out, as in CI; with it they
# run too. Any -L/-LE given is passed on as it is.
set -euo pipefail
figures=0
if [ "${1:-}" = "--figures" ]; then
  figures=1
  shift
fi
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
# ctest starts the longest tests first once it knows their times; a new build
# folder takes them from tests/ctest_costs.txt (a whole run's record on a
# 2-core machine) instead of starting them in the order they were declared.
costs="$build/Testing/Temporary/CTestCostData.txt"
if [ ! -f "$costs" ]; then
  mkdir -p "$(dirname "$costs")"
  cp "$root/tests/ctest_costs.txt" "$costs"
fi
select=()
if [ "$figures" = 0 ]; then
  select=(-LE figure)
  for a in "$@"; do
    case "$a" in -L|-LE|--label-regex|--label-exclude) select=() ;; esac
  done
fi
ctest --output-on-failure --parallel "$(nproc)" --timeout 900 "${select[@]}" "$@"
