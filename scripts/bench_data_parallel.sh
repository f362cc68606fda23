#!/usr/bin/env bash
# Steps a second of one gaussian-style training (stages 1-2 from a training
# pack) run four ways on this machine: one process on one thread taking one
# view a step and two views a step, two ranks (headforge-train under
# torchrun's variables, c10d gloo on localhost) of one thread each taking
# one view a step each, and one process on two threads taking two views a
# step. The pack's own options otherwise (its steps, size, densification).
#   scripts/bench_data_parallel.sh PACK [OUT_DIR] [STEPS]
# Prints a table (markdown) and writes OUT_DIR/results.json.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
train="${HEADFORGE_TRAIN:-$root/build/avatar/headforge-train}"
pack="${1:?usage: bench_data_parallel.sh PACK [OUT_DIR] [STEPS]}"
out="${2:-$(mktemp -d)}"
steps="${3:-200}"
mkdir -p "$out"
common=(--set "steps=$steps" --set eval_every=0 --set preview_every=0 --set checkpoint_every=100000 --set max_minutes=0
        --set decoder_steps=0 --log-level warning)
# The training's own seconds (stats.jsonl's last line), not the start and the final evaluation.
seconds() { python3 -c "import json,sys; print(json.loads(open(sys.argv[1]).read().splitlines()[-1])['seconds'])" "$1/stats.jsonl"; }
run_one() {  # NAME THREADS VIEWS
  rm -rf "$out/$1"
  "$train" "$pack" --out "$out/$1" --threads "$2" --distributed off --set "views_per_step=$3" "${common[@]}" >/dev/null 2>&1
  seconds "$out/$1"
}
run_pair() {  # NAME
  rm -rf "$out/$1"
  local port=$((29700 + RANDOM % 200))
  RANK=1 WORLD_SIZE=2 MASTER_ADDR=127.0.0.1 MASTER_PORT=$port "$train" "$pack" --out "$out/$1" --threads 1 "${common[@]}" \
    >"$out/$1.rank1.log" 2>&1 &
  local one=$!
  RANK=0 WORLD_SIZE=2 MASTER_ADDR=127.0.0.1 MASTER_PORT=$port "$train" "$pack" --out "$out/$1" --threads 1 "${common[@]}" \
    >"$out/$1.rank0.log" 2>&1
  wait "$one"
  seconds "$out/$1"
}
a=$(run_one single 1 1)
b=$(run_one one_thread_two_views 1 2)
c=$(run_pair two_ranks)
d=$(run_one two_threads_two_views 2 2)
cmp -s "$out/two_ranks/model.pt" "$out/one_thread_two_views/model.pt" && same=yes || same=no
python3 - "$out" "$steps" "$a" "$b" "$c" "$d" "$same" <<'PY'
import json, sys
out, steps = sys.argv[1], int(sys.argv[2])
rows = [("one process, 1 thread, 1 view a step", float(sys.argv[3]), 1),
        ("one process, 1 thread, 2 views a step", float(sys.argv[4]), 2),
        ("two ranks (c10d gloo), 1 thread each, 1 view each a step", float(sys.argv[5]), 2),
        ("one process, 2 threads, 2 views a step", float(sys.argv[6]), 2)]
print(f"| {steps} steps | training s | steps/s | views/s |")
print("|---|---|---|---|")
for name, s, v in rows:
    print(f"| {name} | {s:.1f} | {steps / s:.2f} | {steps * v / s:.2f} |")
print(f"two ranks' model.pt the same bytes as one process's with 2 views a step: {sys.argv[7]}")
json.dump({"steps": steps, "rows": [{"run": n, "seconds": s, "views_per_step": v} for n, s, v in rows],
           "two_ranks_equal_one_process": sys.argv[7] == "yes"}, open(out + "/results.json", "w"), indent=1)
PY
