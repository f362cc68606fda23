#!/usr/bin/env bash
# Where the suite's time goes, test by test: every ctest entry run alone,
# one after another, in a built tree, from no shared workspace (as a fresh
# clone starts; the fixtures first, then every entry in ctest's order), with
#   wall   its wall time (s)
#   cpu    the CPU the whole machine spent meanwhile (s, /proc/stat: user,
#          nice, system, irq, softirq), so that what runs outside the test's
#          own processes counts too (Slurm's jobs, Chromium's helpers);
#          run it with nothing else running
# as tab-separated lines on stdout, the dearest first, and a total.
#   scripts/test_profile.sh [REGEX]   only the entries whose names match
#                                     (a shared workspace they need and the
#                                     selection lacks is made inside them)
# Takes about as long as the suite on one core (some 25 minutes here).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${HEADFORGE_BUILD_DIR:-$root/build}"
filter="${1:-.}"
[ -x "$build/pipelines/headforge" ] || { echo "test_profile.sh: no build in $build; run scripts/build.sh" >&2; exit 1; }
cd "$build"
rm -rf test_workspaces tmp
mkdir -p tmp
export TMPDIR="$build/tmp"

busy_ticks() { awk '/^cpu /{print $2 + $3 + $4 + $7 + $8; exit}' /proc/stat; }
hz=$(getconf CLK_TCK)
names=$(ctest -N | sed -n 's/^ *Test *#[0-9]*: //p')
ordered=$( (grep '^train_fixture' <<<"$names" || true; grep -v '^train_fixture' <<<"$names") | grep -E -- "$filter" || true)
[ -n "$ordered" ] || { echo "test_profile.sh: no test matches '$filter'" >&2; exit 1; }
out=$(mktemp)
failed=0
while IFS= read -r name; do
  regex="^$(printf '%s' "$name" | sed 's/[][().*+?^$|\\{}]/\\&/g')\$"
  before=$(busy_ticks)
  start=$(date +%s.%N)
  # -FS/-FC: the fixtures' entries ran first, so no test makes them again.
  # (stdin from /dev/null: a test reading it would eat the list's next names)
  if ctest -R "$regex" -FS '.*' -FC '.*' --timeout 900 > "$build/tmp/profile_last.log" 2>&1 < /dev/null; then
    status=passed
    grep -q "No tests were found" "$build/tmp/profile_last.log" && { status=MISSING; failed=$((failed + 1)); }
  else status=FAILED; failed=$((failed + 1)); fi
  end=$(date +%s.%N)
  after=$(busy_ticks)
  awk -v n="$name" -v s="$start" -v e="$end" -v b="$before" -v a="$after" -v hz="$hz" -v st="$status" \
    'BEGIN {printf "%.1f\t%.1f\t%s\t%s\n", e - s, (a - b) / hz, st, n}' >> "$out"
  tail -1 "$out" >&2
done <<<"$ordered"
printf 'wall\tcpu\tstatus\ttest\n'
sort -t$'\t' -k2 -n -r "$out"
awk -F'\t' '{w += $1; c += $2} END {printf "%.1f\t%.1f\ttotal\t%d entries\n", w, c, NR}' "$out"
rm -f "$out"
[ "$failed" -eq 0 ]
