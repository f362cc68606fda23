#!/usr/bin/env bash
# The GPU figures in one device window (docs/gpu.md). Three uses:
#
#   scripts/gpu_check.sh --prepare [DIR]       here, on the CPU, beforehand
#     makes the training packs the check trains on, from tracked workspaces
#     (talking_static simulated and tracked, one GRID clip tracked, in
#     BUILD_DIR/gpu_check_prepare): gaussian-style `standard` on both,
#     gan-avatar `standard` on talking_static, each compressed with xz,
#     beside manifest.json and deps.tar.xz (Debian's Eigen, nlohmann-json,
#     GoogleTest and Google Benchmark, which the GPU machine lacks), into DIR
#     (default gpu_packs/, ignored by git); says their sizes and whether DIR
#     and the working tree fit the 64 MiB a device call carries.
#     --workspace WS / --grid-workspace WS: tracked workspaces to pack instead;
#     --grid-clip NAME (default bbaf2n) of DATA/video/grid; --frames N:
#     simulate fewer talking_static frames (smaller packs); --data DIR.
#
#   scripts/gpu_check.sh [--device cuda] [--packs DIR] [--out DIR] [options]
#     on the GPU machine, within 9 minutes with the build: builds
#     headforge-train, the benchmark and avatar_cuda_test (scripts/train_cuda.sh
#     in build-cuda/, reused when it is this tree's), runs the rasterizer
#     benchmark (100k Gaussians, 512², C = 3 and 32), trains each pack for its
#     minutes and measures held-out PSNR/SSIM, step time, peak GPU memory and
#     render speed, then runs the GPU tests in the time left; writes
#     gpu_check.json, gpu_check.md and gpu_check_logs.tar.gz to --out (default
#     $OUT, else gpu_check_out/), the report after every step. A step that
#     fails is recorded and the next one runs.
#
#   scripts/gpu_check.sh --device cpu --tiny --workspace WS [--build-dir build]
#     the same steps on tiny settings on the CPU (tiny packs of the tracked
#     workspace WS, seconds of training, the rasterizer at 10k and 256²), with
#     the programs of the build folder: the dry run CI runs (gpu_check_test).
#
# The measuring steps' options (minutes per training, the deadline) are
# scripts/gpu_check.py's, listed below this text by --help.
# scripts/gpu_table.py turns gpu_check.json into docs/benchmarks' table.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

prepare="" tiny=0 device=cuda workspace="" grid_workspace="" build_dir="" work="" threads=0 frames="" headforge=""
data="${HEADFORGE_DATA:-$root/../shared/data}" grid_clip=bbaf2n
measure_args=()
while [ $# -gt 0 ]; do
  case "$1" in
    --prepare)
      prepare="$root/gpu_packs"
      if [ $# -gt 1 ] && [ "${2#--}" = "$2" ]; then prepare="$2"; shift; fi ;;
    --tiny) tiny=1 ;;
    --device) device="$2"; shift ;;
    --workspace) workspace="$2"; shift ;;
    --grid-workspace) grid_workspace="$2"; shift ;;
    --build-dir) build_dir="$2"; shift ;;
    --work) work="$2"; shift ;;
    --threads) threads="$2"; shift ;;
    --data) data="$2"; shift ;;
    --grid-clip) grid_clip="$2"; shift ;;
    --frames) frames="$2"; shift ;;
    --headforge) headforge="$2"; shift ;;
    -h|--help)
      sed -n '2,35p' "$0" | sed 's/^# \{0,1\}//'
      echo
      exec python3 "$root/scripts/gpu_check.py" --help ;;
    *) measure_args+=("$1") ;;
  esac
  shift
done

fail() {
  echo "gpu_check.sh: $*" >&2
  exit 1
}

# The size of what travels to the device machine besides DIR: tracked files
# and untracked ones git does not ignore.
tree_bytes() {
  (cd "$root" && git ls-files -z -co --exclude-standard | xargs -0 -r stat -c %s -- 2>/dev/null |
    awk '{s += $1} END {print s + 0}')
}

# pack_run DIR WORKSPACE NAME MODEL CAPTURE PRESET XZ_LEVEL [headforge pack options]:
# one pack, compressed into DIR, and its line of the manifest (DIR/runs.tsv).
pack_run() {
  local dir="$1" ws="$2" name="$3" model="$4" capture="$5" preset="$6" level="$7"
  shift 7
  local pack="$dir/$name.pack"
  echo "gpu_check.sh: packing $name ($model, $preset) from $ws" >&2
  "$headforge" pack --workspace "$ws" --model "$model" --preset "$preset" --out "$pack" \
    --threads "$threads" --log-level warning "$@" >&2 ||
    fail "headforge pack failed for $name"
  local bytes
  bytes=$(stat -c %s "$pack")
  xz -T0 "-$level" -f "$pack"
  printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$name" "$model" "$preset" "$capture" "$name.pack.xz" "$bytes" >>"$dir/runs.tsv"
}

# The manifest the measuring steps read: each run's pack and what it is.
write_manifest() {
  local dir="$1" kind="$2"
  python3 - "$dir" "$kind" "$(cd "$root" && git rev-parse --short=12 HEAD 2>/dev/null || echo unknown)" \
    "$headforge" <<'EOF'
import json, sys, time
from pathlib import Path
folder, kind, commit, program = Path(sys.argv[1]), sys.argv[2], sys.argv[3], Path(sys.argv[4])
runs = []
for line in (folder / "runs.tsv").read_text().splitlines():
    name, model, preset, capture, pack, size = line.split("\t")
    entry = {"name": name, "model": model, "preset": preset, "capture": capture, "pack": pack,
             "pack_bytes": int(size), "xz_bytes": (folder / pack).stat().st_size}
    runs.append(entry)
(folder / "manifest.json").write_text(json.dumps(
    {"kind": kind, "made": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "commit": commit,
     "made_with": f"{program.resolve()} (built {time.strftime('%Y-%m-%dT%H:%M', time.gmtime(program.stat().st_mtime))})",
     "runs": runs}, indent=1) + "\n")
EOF
  rm -f "$dir/runs.tsv"
}

# Debian's headers, CMake files and libraries of what the GPU build needs
# besides LibTorch, in /usr's layout (their CMake files find the rest from
# where they sit): Eigen, nlohmann-json, GoogleTest, Google Benchmark.
bundle_deps() {
  local dir="$1" stage="$work/deps_stage" arch=x86_64-linux-gnu
  rm -rf "$stage"
  mkdir -p "$stage/include" "$stage/share/cmake" "$stage/share/eigen3" "$stage/lib/$arch/cmake"
  local missing=()
  copy() {  # copy SOURCE... DESTINATION-FOLDER
    local to="${*: -1}" from
    for from in "${@:1:$#-1}"; do
      if [ -e "$from" ]; then cp -a "$from" "$to/"; else missing+=("$from"); fi
    done
  }
  copy /usr/include/eigen3 /usr/include/nlohmann /usr/include/gtest /usr/include/gmock /usr/include/benchmark \
    "$stage/include"
  copy /usr/share/eigen3/cmake "$stage/share/eigen3"
  copy /usr/share/cmake/nlohmann_json "$stage/share/cmake"
  copy /usr/lib/$arch/cmake/GTest /usr/lib/$arch/cmake/benchmark "$stage/lib/$arch/cmake"
  copy /usr/lib/$arch/libgtest.a /usr/lib/$arch/libgtest_main.a /usr/lib/$arch/libgmock.a \
    /usr/lib/$arch/libgmock_main.a /usr/lib/$arch/libbenchmark.so /usr/lib/$arch/libbenchmark.so.1.7.1 \
    /usr/lib/$arch/libbenchmark.so.1debian /usr/lib/$arch/libbenchmark_main.a "$stage/lib/$arch"
  [ ${#missing[@]} -eq 0 ] || echo "gpu_check.sh: not bundled (not on this machine): ${missing[*]}" >&2
  tar -C "$stage" -cJf "$dir/deps.tar.xz" .
  rm -rf "$stage"
}

# simulate + run --until track of talking_static, into $work (skipped where done).
track_talking_static() {
  local sim="$work/talking_static_sim" ws="$work/talking_static"
  if [ ! -f "$sim/ground_truth.json" ]; then
    "$headforge" simulate --scene "$root/scenes/talking_static.toml" --out "$sim" --threads "$threads" \
      ${frames:+--frames "$frames"} >&2 || fail "headforge simulate failed"
  fi
  local inputs=()
  mapfile -t inputs < <(python3 -c 'import json, sys, os
truth = json.load(open(os.path.join(sys.argv[1], "ground_truth.json")))
for cam in truth["cameras"]: print(os.path.join(sys.argv[1], cam["input"]))' "$sim")
  "$headforge" run --video "${inputs[@]}" --workspace "$ws" --until track --threads "$threads" >&2 ||
    fail "headforge run --until track failed on talking_static"
  echo "$ws"
}

track_grid() {
  local clip="$data/video/grid/$grid_clip.mpg" ws="$work/$grid_clip"
  [ -f "$clip" ] || fail "no GRID clip at $clip (--data, --grid-clip)"
  "$headforge" run --video "$clip" --workspace "$ws" --until track --threads "$threads" >&2 ||
    fail "headforge run --until track failed on $clip"
  echo "$ws"
}

if [ -n "$prepare" ]; then
  build_dir="${build_dir:-$root/build}"
  work="${work:-$build_dir/gpu_check_prepare}"
  headforge="${headforge:-$build_dir/pipelines/headforge}"
  [ -x "$headforge" ] || fail "no headforge at $headforge (scripts/build.sh, or --build-dir)"
  mkdir -p "$work" "$prepare"
  prepare="$(cd "$prepare" && pwd)"
  rm -f "$prepare"/*.pack.xz "$prepare/manifest.json" "$prepare/runs.tsv"
  ts="$workspace"
  [ -n "$ts" ] || ts="$(track_talking_static)"
  grid="$grid_workspace"
  [ -n "$grid" ] || grid="$(track_grid)"
  grid_name="$(basename "$grid")"
  [ -n "$grid_workspace" ] || grid_name="$grid_clip"
  pack_run "$prepare" "$ts" gaussian_style_talking_static gaussian-style "talking_static" standard 6 \
    --decoder-steps 0 --preview-every 0
  pack_run "$prepare" "$grid" "gaussian_style_$grid_name" gaussian-style "GRID $grid_name" standard 6 \
    --decoder-steps 0 --preview-every 0
  pack_run "$prepare" "$ts" gan_avatar_talking_static gan-avatar "talking_static" standard 6 --preview-every 0
  write_manifest "$prepare" prepared
  bundle_deps "$prepare"
  packs=$(du -cb "$prepare"/* | tail -1 | cut -f1)
  tree=$(tree_bytes)
  limit=$((64 << 20))
  echo "gpu_check.sh: in $prepare:" >&2
  (cd "$prepare" && ls -l --block-size=K ./*.xz manifest.json) >&2
  python3 -c 'import json, sys
for r in json.load(open(sys.argv[1]))["runs"]:
    print("  %-34s %6.1f MiB, %5.1f MiB as .xz" % (r["name"], r["pack_bytes"] / 2**20, r["xz_bytes"] / 2**20))' \
    "$prepare/manifest.json" >&2
  awk -v p="$packs" -v t="$tree" 'BEGIN {
    printf "gpu_check.sh: %.1f MiB here + %.1f MiB of the working tree = %.1f of the 64 MiB a device call carries\n",
      p / 1048576, t / 1048576, (p + t) / 1048576 }' >&2
  if [ $((packs + tree)) -gt "$limit" ]; then
    fail "too large to carry: make the packs smaller (--frames N simulates fewer talking_static frames)"
  fi
  exit 0
fi

if [ "$tiny" = 1 ]; then
  [ "$device" = cpu ] || fail "--tiny is the CPU dry run: give --device cpu"
  [ -n "$workspace" ] || fail "--tiny needs --workspace WS, a tracked workspace to make its tiny packs from"
  build_dir="${build_dir:-$root/build}"
  work="${work:-$build_dir/gpu_check}"
  headforge="${headforge:-$build_dir/pipelines/headforge}"
  [ -x "$headforge" ] || fail "no headforge at $headforge (--build-dir, or --headforge)"
  packs="$work/packs"
  rm -rf "$packs"
  mkdir -p "$packs"
  # Tiny: 48 px (the gan-avatar 32 px from a 16 px render), a hundred-odd steps.
  gs_tiny=(--device cpu --train.resolution 48 --steps 60 --canonical-fraction 0.5 --init-gaussians 1500
    --max-gaussians 2500 --densify-from 10 --densify-every 10 --densify-until 40 --eval-every 0 --preview-every 0
    --log-every 5 --decoder-steps 0)
  gan_tiny=(--device cpu --train.resolution 32 --render-resolution 16 --samples 8 --fine-samples 8 --batch 2
    --triplane-resolution 16 --steps 20 --reconstruction-steps 10 --r1-every 2 --log-every 5 --eval-every 0
    --preview-every 0 --mapping-steps 0)
  pack_run "$packs" "$workspace" gaussian_style_talking_static gaussian-style \
    "$(basename "$workspace") (tiny)" draft 0 "${gs_tiny[@]}"
  if [ -n "$grid_workspace" ]; then
    pack_run "$packs" "$grid_workspace" gaussian_style_grid gaussian-style "$(basename "$grid_workspace") (tiny)" \
      draft 0 "${gs_tiny[@]}"
  else  # the same pack in the GRID clip's place
    cp "$packs/gaussian_style_talking_static.pack.xz" "$packs/gaussian_style_grid.pack.xz"
    tail -n 1 "$packs/runs.tsv" | awk -F '\t' -v OFS='\t' '{ $1 = "gaussian_style_grid"; $5 = $1 ".pack.xz";
      $4 = $4 ", in the GRID clip'"'"'s place"; print }' >>"$packs/runs.tsv"
  fi
  pack_run "$packs" "$workspace" gan_avatar_talking_static gan-avatar "$(basename "$workspace") (tiny)" draft 0 \
    "${gan_tiny[@]}"
  write_manifest "$packs" tiny
  exec python3 "$root/scripts/gpu_check.py" --device cpu --tiny --packs "$packs" --build-dir "$build_dir" \
    --work "$work" --headforge "$headforge" --threads "$threads" "${measure_args[@]}"
fi

[ "$device" != cpu ] || fail "--device cpu is the dry run: give --tiny and --workspace WS too"
exec python3 "$root/scripts/gpu_check.py" --device "$device" ${build_dir:+--build-dir "$build_dir"} \
  ${work:+--work "$work"} --threads "$threads" "${measure_args[@]}"
