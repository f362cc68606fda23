#!/usr/bin/env python3
"""The measuring half of scripts/gpu_check.sh (run it through that script).

Given a folder of training packs and its manifest.json (what
`scripts/gpu_check.sh --prepare` writes), it runs the check's steps in order:
the machine's description, the build of headforge-train (through
scripts/train_cuda.sh, on a GPU machine), the rasterizer benchmark, each
pack trained by headforge-train for its minutes, with its held-out scores,
step time, peak memory and render speed, then the rasterizer's GPU tests in
the time left. A step that fails is recorded with its error and the next
one runs. The
report is one JSON file (gpu_check.json) and its table (gpu_check.md,
scripts/gpu_table.py) in --out. Python 3 standard library only: the GPU
machine has python3 (with PyTorch) and little else.
"""
import argparse
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tarfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.dont_write_bytecode = True  # no __pycache__ in scripts/
import gpu_table  # noqa: E402  (beside this file)

REPORT_VERSION = 1
# The rasterizer benchmark's sizes: the on a GPU, the smallest in
# the dry run.
BENCH_FILTER = {"cuda": "N:100000/side:512/", "cpu": "N:10000/side:256/"}
# What a training needs besides its minutes: loading the pack, the final
# evaluation (every held-out view, every tenth training view), saving.
TRAIN_OVERHEAD_MIN = {"cuda": 0.6, "cpu": 0.3}


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="scripts/gpu_check.sh",
        description="The GPU figures in one device window (see scripts/gpu_check.sh and docs/gpu.md).")
    p.add_argument("--device", default="cuda", help="cuda (the check) or cpu (the dry run, with --tiny)")
    p.add_argument("--tiny", action="store_true", help="tiny settings: seconds per step (the CPU dry run)")
    p.add_argument("--packs", default=str(ROOT / "gpu_packs"), help="the packs and manifest.json (--prepare's)")
    p.add_argument("--out", default=os.environ.get("OUT") or str(ROOT / "gpu_check_out"),
                   help="where gpu_check.json, gpu_check.md and the logs go (default $OUT, else gpu_check_out/)")
    p.add_argument("--build-dir", help="the build folder (cuda: build-cuda/, built here; cpu: build/, built before)")
    p.add_argument("--work", help="unpacked packs, models and logs (default BUILD_DIR/gpu_check)")
    p.add_argument("--headforge-train", help="the program (default BUILD_DIR/avatar/headforge-train)")
    p.add_argument("--splat-bench", help="the benchmark (default BUILD_DIR/bench/headforge_splat_bench)")
    p.add_argument("--headforge", help="for the dry run's description of LibTorch (default BUILD_DIR/pipelines/headforge)")
    p.add_argument("--no-build", action="store_true", help="cuda: use BUILD_DIR as it is")
    p.add_argument("--no-cuda-tests", action="store_true", help="cuda: neither build nor run avatar_cuda_test")
    p.add_argument("--gs-minutes", type=float,
                   help="training minutes of gaussian-style on talking_static (default 1.5; --tiny 0.5)")
    p.add_argument("--grid-minutes", type=float,
                   help="training minutes of gaussian-style on the GRID clip (default 2; --tiny 0.5)")
    p.add_argument("--gan-minutes", type=float, help="training minutes of gan-avatar (default 1.5; --tiny 0.5)")
    p.add_argument("--gs-steps", type=int, default=3000,
                   help="gaussian-style's steps, so that stage 2 (a quarter in) comes within the minutes (default "
                        "3000; 0: the pack's)")
    p.add_argument("--deadline-minutes", type=float, default=9.0,
                   help="the whole check's wall time, build included: trainings are shortened to fit (default 9)")
    p.add_argument("--threads", type=int, default=0, help="headforge-train's --threads (0: its default)")
    a = p.parse_args(argv)
    if a.device not in ("cuda", "cpu") and not a.device.startswith("cuda:"):
        p.error("--device must be cuda, cuda:N or cpu")
    if a.device == "cpu" and not a.tiny:
        p.error("--device cpu is the dry run: give --tiny too")
    cuda = a.device != "cpu"
    for name, default in (("gs_minutes", 1.5), ("grid_minutes", 2.0), ("gan_minutes", 1.5)):
        if getattr(a, name) is None:
            setattr(a, name, 0.5 if a.tiny else default)
    a.build_dir = Path(a.build_dir or ROOT / ("build-cuda" if cuda else "build")).resolve()
    a.work = Path(a.work or a.build_dir / "gpu_check").resolve()
    a.headforge_train = Path(a.headforge_train or a.build_dir / "avatar" / "headforge-train")
    a.splat_bench = Path(a.splat_bench or a.build_dir / "bench" / "headforge_splat_bench")
    a.headforge = Path(a.headforge or a.build_dir / "pipelines" / "headforge")
    a.packs = Path(a.packs).resolve()
    a.out = Path(a.out).resolve()
    a.kind = "cuda" if cuda else "cpu"
    return a


class Deadline:
    def __init__(self, minutes):
        self.start = time.monotonic()
        self.end = self.start + 60 * minutes

    def left_min(self):
        return (self.end - time.monotonic()) / 60

    def elapsed_s(self):
        return time.monotonic() - self.start


def tail(path, chars=1500):
    try:
        text = Path(path).read_text(errors="replace")
    except OSError:
        return ""
    return text[-chars:]


def run(cmd, log, timeout_s, env=None, cwd=None, on_start=None):
    """Runs `cmd` with its output into `log`; returns (exit code or None when
    it was stopped at `timeout_s`, seconds, peak resident memory in MiB)."""
    log.parent.mkdir(parents=True, exist_ok=True)
    start = time.monotonic()
    with open(log, "w") as out:
        out.write("$ " + " ".join(str(c) for c in cmd) + "\n")
        out.flush()
        proc = subprocess.Popen([str(c) for c in cmd], stdout=out, stderr=subprocess.STDOUT, env=env, cwd=cwd,
                                start_new_session=True)
        if on_start:
            on_start(proc)
        code, usage = None, None
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid == proc.pid:
                code = os.waitstatus_to_exitcode(status)
                break
            if time.monotonic() - start > timeout_s:
                for sig, grace in ((signal.SIGTERM, 15), (signal.SIGKILL, 5)):
                    try:
                        os.killpg(proc.pid, sig)
                    except ProcessLookupError:
                        pass
                    stop = time.monotonic() + grace
                    while time.monotonic() < stop:
                        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
                        if pid == proc.pid:
                            break
                        time.sleep(0.2)
                    if pid == proc.pid:
                        break
                code = None
                break
            time.sleep(0.1)
        proc.returncode = 0  # reaped here by wait4
    peak = usage.ru_maxrss / 1024 if usage else None  # KiB on Linux
    return code, time.monotonic() - start, peak


class GpuMemory:
    """The GPU's used memory sampled by nvidia-smi every 200 ms while a
    command runs: the peak over it, less what was in use before (the whole
    card's figure: the CUDA context and LibTorch's cached blocks included)."""

    def __init__(self, index):
        self.index = str(index)
        self.peak = None
        self.base = self.query()
        self.proc = None

    def query(self):
        try:
            out = subprocess.run(["nvidia-smi", "-i", self.index, "--query-gpu=memory.used",
                                  "--format=csv,noheader,nounits"], capture_output=True, text=True, timeout=20)
            return float(out.stdout.split()[0])
        except (OSError, ValueError, IndexError, subprocess.SubprocessError):
            return None

    def start(self, _proc=None):
        if self.base is None:
            return
        self.proc = subprocess.Popen(["nvidia-smi", "-i", self.index, "--query-gpu=memory.used",
                                      "--format=csv,noheader,nounits", "-lms", "200"],
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            try:
                value = float(line.strip())
            except ValueError:
                continue
            self.peak = value if self.peak is None else max(self.peak, value)

    def stop(self):
        if self.proc:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        if self.peak is None or self.base is None:
            return None
        return self.peak - self.base


def finite(x):
    return isinstance(x, (int, float)) and math.isfinite(x)


def machine(args):
    """The card, its driver, PyTorch, the compiler, the CPU, the commit."""
    m = {"device": args.device, "cores": os.cpu_count()}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                m["cpu"] = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    def output(cmd, timeout=60):
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
            return r.stdout.strip() if r.returncode == 0 else None
        except (OSError, subprocess.SubprocessError):
            return None
    if args.kind == "cuda":
        gpu = output(["nvidia-smi", "--query-gpu=name,driver_version,memory.total", "--format=csv,noheader"])
        if gpu:
            first = [f.strip() for f in gpu.splitlines()[0].split(",")]
            m["card"], m["driver"] = first[0], first[1] if len(first) > 1 else None
            m["card_memory"] = first[2] if len(first) > 2 else None
            m["gpus"] = len(gpu.splitlines())
        nvcc = output(["nvcc", "--version"])
        if nvcc:
            m["nvcc"] = nvcc.splitlines()[-1]
    if args.kind == "cuda":  # the LibTorch the build takes: python3's
        torch = output([sys.executable, "-c", "import torch; print(torch.__version__); print(torch.version.cuda)"],
                       120)
        if torch:
            lines = torch.splitlines()
            m["torch"] = lines[0]
            m["torch_cuda"] = lines[1] if len(lines) > 1 and lines[1] != "None" else None
    elif args.headforge.exists():  # the one the programs of the build folder were built with
        version = output([str(args.headforge), "version"])
        found = re.search(r"LibTorch\s*([\w.+-]+)", version or "", re.I)
        m["torch"] = "LibTorch " + found.group(1) if found else None
    m["commit"] = output(["git", "rev-parse", "--short=12", "HEAD"])
    m["python"] = sys.version.split()[0]
    return m


def step_result(name, **fields):
    r = {"name": name, "ok": False, "error": None, "seconds": None}
    r.update(fields)
    return r


def cmake_cache(build):
    values = {}
    try:
        for line in (build / "CMakeCache.txt").read_text().splitlines():
            m = re.match(r"^([A-Za-z_][\w]*):[A-Z]+=(.*)$", line)
            if m:
                values[m.group(1)] = m.group(2)
    except OSError:
        pass
    return values


def unpack_deps(args):
    """Debian's headers and libraries that the GPU machine lacks (Eigen,
    nlohmann-json, GoogleTest, Google Benchmark), as --prepare bundled
    them: a prefix for CMake, or None."""
    bundle = args.packs / "deps.tar.xz"
    if not bundle.exists():
        return None
    prefix = args.work / "deps"
    stamp = prefix / ".unpacked"
    if not (stamp.exists() and stamp.read_text() == str(bundle.stat().st_size)):
        shutil.rmtree(prefix, ignore_errors=True)
        prefix.mkdir(parents=True)
        with tarfile.open(bundle, "r:xz") as tar:
            try:
                tar.extractall(prefix, filter="data")
            except TypeError:  # a Python without extraction filters
                tar.extractall(prefix)
        stamp.write_text(str(bundle.stat().st_size))
    return prefix


def build(args, deadline, report):
    """headforge-train, the benchmark and the GPU tests through
    scripts/train_cuda.sh; a build folder carried from another tree or
    another LibTorch is started afresh, one that matches is reused."""
    r = step_result("build", build_dir=str(args.build_dir), attempts=[])
    report["steps"].append(r)
    start = time.monotonic()
    try:
        cache = cmake_cache(args.build_dir)
        if cache:
            home = cache.get("CMAKE_HOME_DIRECTORY", "")
            same = home and Path(home).resolve() == ROOT
            r["reused"] = bool(same)
            if not same:  # (the work folder inside it goes too, before anything is unpacked there)
                r["started_afresh"] = "its cache is for " + home
                shutil.rmtree(args.build_dir, ignore_errors=True)
        prefix = unpack_deps(args)
        r["deps"] = str(prefix) if prefix else "the machine's own"
        env = dict(os.environ, HEADFORGE_CUDA_BUILD_DIR=str(args.build_dir))
        if prefix:
            env["CMAKE_PREFIX_PATH"] = str(prefix) + (":" + env["CMAKE_PREFIX_PATH"]
                                                     if env.get("CMAKE_PREFIX_PATH") else "")
        tries = [("ON", "ON"), ("OFF", "ON"), ("OFF", "OFF")]
        if args.no_cuda_tests:
            tries = tries[1:]
        for tests, bench in tries:
            env.update(HEADFORGE_CUDA_TESTS=tests, HEADFORGE_CUDA_BENCHMARKS=bench)
            log = args.work / "logs" / f"build_tests{tests}_bench{bench}.log"
            left = max(60.0, 60 * deadline.left_min() - 60)
            code, seconds, _ = run(["bash", ROOT / "scripts" / "train_cuda.sh"], log, left, env=env)
            attempt = {"tests": tests == "ON", "benchmark": bench == "ON", "seconds": round(seconds, 1),
                       "exit": code, "log": log.name}
            r["attempts"].append(attempt)
            if code == 0:
                r["ok"] = True
                r["tests"], r["benchmark"] = tests == "ON", bench == "ON"
                break
            attempt["error"] = tail(log)
            if code is None:
                break  # out of time: no smaller build would fit either
        if not r["ok"]:
            r["error"] = "scripts/train_cuda.sh failed: " + (r["attempts"][-1].get("error") or "")[-800:]
    except Exception as e:  # recorded, and the next step runs
        r["error"] = f"{type(e).__name__}: {e}"
    r["seconds"] = round(time.monotonic() - start, 1)


def cuda_tests(args, deadline, report):
    r = step_result("cuda_tests")
    report["steps"].append(r)
    binary = args.build_dir / "avatar" / "avatar_cuda_test"
    if not binary.exists():
        r["error"] = "not built (GoogleTest missing, or the build failed): " + str(binary)
        return
    limit = min(120.0, 60 * deadline.left_min())
    if limit < 20:
        r["error"] = f"skipped: {limit:.0f} s left before the deadline"
        return
    log = args.work / "logs" / "avatar_cuda_test.log"
    code, seconds, _ = run([binary, "--gtest_brief=1"], log, limit)
    r["seconds"] = round(seconds, 1)
    text = tail(log, 20000)
    passed = re.search(r"\[  PASSED  \] (\d+) test", text)
    failed = re.findall(r"\[  FAILED  \] (\S+)", text)
    r["passed"] = int(passed.group(1)) if passed else 0
    r["failed"] = sorted(set(f for f in failed if not f[0].isdigit()))
    r["ok"] = code == 0
    if code is not None and code != 0:
        r["error"] = "avatar_cuda_test: " + tail(log, 800)
    if code is None:
        r["error"] = f"stopped after {limit:.0f} s"


def rasterizer(args, report):
    """headforge_splat_bench's forward, backward and both at one size, C = 3
    and 32 (100k Gaussians at 512² on a GPU)."""
    r = step_result("rasterizer", filter=BENCH_FILTER[args.kind], results=[])
    report["steps"].append(r)
    if not args.splat_bench.exists():
        r["error"] = "no benchmark program at " + str(args.splat_bench)
        return
    out = args.work / "splat_bench.json"
    out.unlink(missing_ok=True)
    cmd = [args.splat_bench, "--device=" + ("cuda" if args.kind == "cuda" else "cpu"),
           "--benchmark_filter=" + BENCH_FILTER[args.kind], "--benchmark_out=" + str(out),
           "--benchmark_out_format=json"]
    if args.tiny:
        cmd.append("--benchmark_min_time=0.05")
    log = args.work / "logs" / "splat_bench.log"
    code, seconds, _ = run(cmd, log, 300)
    r["seconds"] = round(seconds, 1)
    try:
        data = json.loads(out.read_text())
    except (OSError, ValueError) as e:
        r["error"] = f"no benchmark output ({e}): " + tail(log, 800)
        return
    rows = {}
    for b in data.get("benchmarks", []):
        m = re.match(r"BM_Splat(\w+)/N:(\d+)/side:(\d+)/C:(\d+)", b.get("name", ""))
        if not m or b.get("error_occurred"):
            continue
        scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[b.get("time_unit", "ns")]
        row = rows.setdefault((int(m.group(4)), int(m.group(2)), int(m.group(3))), {})
        key = {"Forward": "forward_ms", "Backward": "backward_ms", "ForwardBackward": "forward_backward_ms"}
        row[key[m.group(1)]] = b["real_time"] * scale
        if m.group(1) == "ForwardBackward" and "peak_MiB" in b:
            row["peak_mib"] = b["peak_MiB"]
    for (channels, n, side), row in sorted(rows.items()):
        r["results"].append(dict(channels=channels, gaussians=n, side=side, **row))
    r["context"] = {k: data.get("context", {}).get(k) for k in ("torch", "device", "threads", "library_build_type")}
    r["ok"] = code == 0 and len(r["results"]) == 2 and all(
        finite(x.get("forward_backward_ms")) for x in r["results"])
    if not r["ok"]:
        r["error"] = f"exit {code}, {len(r['results'])} sizes measured: " + tail(log, 800)


def read_json(path):
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def training_lines(stats_path):
    """stats.jsonl's lines of training steps (not the evaluations')."""
    lines = []
    try:
        text = Path(stats_path).read_text()
    except OSError:
        return lines
    for row in text.splitlines():
        try:
            line = json.loads(row)
        except ValueError:
            continue
        if "step" in line and "seconds" in line and ("loss" in line or "loss_g" in line):
            lines.append(line)
    return lines


def step_times(lines):
    """Milliseconds a step from the training lines, overall and by stage,
    the first logged interval (which holds the start) left out."""
    def rate(ls):
        if len(ls) >= 3:
            ls = ls[1:]
        if len(ls) < 2 or ls[-1]["step"] <= ls[0]["step"]:
            return None
        return 1000 * (ls[-1]["seconds"] - ls[0]["seconds"]) / (ls[-1]["step"] - ls[0]["step"])
    by_stage = {}
    for line in lines:
        if "stage" in line:
            by_stage.setdefault(str(line["stage"]), []).append(line)
    stages = {k: rate(v) for k, v in by_stage.items()}
    return rate(lines), {k: v for k, v in stages.items() if v is not None}


def unpack(args, entry):
    """The run's pack, from its .xz where it came compressed."""
    source = args.packs / entry["pack"]
    if source.suffix != ".xz":
        return source
    target = args.work / "packs" / source.stem
    size = entry.get("pack_bytes")
    if not (target.exists() and size and target.stat().st_size == size):
        target.parent.mkdir(parents=True, exist_ok=True)
        partial = target.with_suffix(".partial")
        try:
            import lzma
        except ImportError:  # a Python built without it: the xz program
            with open(partial, "wb") as dst:
                subprocess.run(["xz", "-dc", str(source)], stdout=dst, check=True)
        else:
            with lzma.open(source) as src, open(partial, "wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 22)
        partial.replace(target)
    return target


def mib(size):
    return round(size / 2**20, 1) if isinstance(size, int) else None


def train(args, entry, minutes, deadline, report):
    r = step_result(entry["name"], model=entry["model"], preset=entry.get("preset"), capture=entry.get("capture"),
                    pack=entry["pack"], pack_mib=mib(entry.get("pack_bytes")), pack_xz_mib=mib(entry.get("xz_bytes")))
    report["steps"].append(r)
    start = time.monotonic()
    try:
        # This training and those after it share what is left before the
        # deadline: each keeps its minutes when they fit, else all shrink alike.
        overhead = TRAIN_OVERHEAD_MIN[args.kind]
        runs = report["_runs"]
        ahead = runs[runs.index(entry):]
        wanted = sum(report["_minutes"][e["name"]] for e in ahead)
        room = deadline.left_min() - overhead * len(ahead)
        given = minutes if room >= wanted else minutes * max(room, 0) / wanted
        r["minutes_asked"] = minutes
        r["minutes"] = round(given, 2)
        if given < 0.05:
            r["error"] = f"skipped: {deadline.left_min():.1f} min left before the deadline"
            return
        if given < minutes:
            r["shortened"] = "to fit the deadline"
        if not args.headforge_train.exists():
            r["error"] = "no headforge-train at " + str(args.headforge_train)
            return
        pack = unpack(args, entry)
        out = args.work / "models" / entry["name"]
        shutil.rmtree(out, ignore_errors=True)  # a run left there would resume, not start
        settings = list(entry.get("settings", []))
        if entry["model"] == "gaussian-style" and args.gs_steps > 0 and not args.tiny:
            settings.append(f"steps={args.gs_steps}")
        r["settings"] = settings
        cmd = [args.headforge_train, pack, "--out", out, "--device", args.device, "--max-minutes", f"{given:.3f}"]
        for s in settings:
            cmd += ["--set", s]
        if args.threads > 0:
            cmd += ["--threads", str(args.threads)]
        r["command"] = " ".join(str(c) for c in [Path(cmd[0]).name, pack.name] + cmd[2:])
        memory = GpuMemory(args.device.partition(":")[2] or 0) if args.kind == "cuda" else None
        log = args.work / "logs" / f"{entry['name']}.log"
        limit = 60 * (given + overhead) + 120
        code, seconds, rss = run(cmd, log, limit, on_start=memory.start if memory else None)
        gpu_peak = memory.stop() if memory else None
        r["wall_seconds"] = round(seconds, 1)
        if args.kind == "cuda":
            r["peak_memory_mib"] = round(gpu_peak) if gpu_peak is not None else None
            r["peak_memory_kind"] = "GPU, nvidia-smi's used memory over the run less before it"
        else:
            r["peak_memory_mib"] = round(rss) if rss is not None else None
            r["peak_memory_kind"] = "resident (CPU)"
        r["peak_resident_mib"] = round(rss) if rss is not None else None
        if code != 0:
            r["error"] = ("stopped after %.0f s" % limit if code is None else f"exit {code}") + ": " + tail(log, 800)
            return
        r.update(figures(out, entry["model"]))
        missing = [k for k in ("psnr_head", "ssim_head", "step_ms") if not finite(r.get(k))]
        r["ok"] = not missing
        if missing:
            r["error"] = "no " + ", ".join(missing) + " in eval.json / stats.jsonl"
    except Exception as e:  # recorded, and the next step runs
        r["error"] = f"{type(e).__name__}: {e}"
    finally:
        r["seconds"] = round(time.monotonic() - start, 1)


def figures(out, model):
    """What a trained model folder says of itself."""
    f = {}
    ev = read_json(out / "eval.json") or {}
    config = read_json(out / "config.json") or {}
    mean = ev.get("mean", {})
    f["psnr_head"], f["ssim_head"] = mean.get("psnr_masked"), mean.get("ssim_masked")
    f["psnr_frame"], f["ssim_frame"] = mean.get("psnr"), mean.get("ssim")
    f["held_out_views"] = len(ev.get("views", []))
    f["held_out_frames"] = ev.get("held_out_frames")
    f["psnr_training_views"] = ev.get("training_views", {}).get("psnr_masked")
    if model == "gan-avatar":
        f["latent"] = ev.get("latent")
    lines = training_lines(out / "stats.jsonl")
    training = config.get("training", {})
    f["steps"] = training.get("steps") or (lines[-1]["step"] if lines else None)
    f["train_seconds"] = training.get("seconds") or (lines[-1]["seconds"] if lines else None)
    f["gaussians"] = config.get("gaussians")
    # The size a held-out view is drawn at: the views' (gaussian-style), the
    # output's (gan-avatar).
    size = [config["width"], config["height"]] if "width" in config else config.get("output_size")
    f["render_size"] = f"{size[0]}×{size[1]}" if isinstance(size, list) and len(size) == 2 else None
    step_ms, by_stage = step_times(lines)
    if step_ms is None and finite(f["train_seconds"]) and f["steps"]:
        step_ms = 1000 * f["train_seconds"] / f["steps"]
    f["step_ms"] = step_ms
    if by_stage:
        f["step_ms_by_stage"] = by_stage
    render_ms = ev.get("render_ms")
    f["render_ms"] = render_ms
    f["render_fps"] = 1000 / render_ms if finite(render_ms) and render_ms > 0 else None
    if f["render_fps"] is None:
        f["render_note"] = "eval.json has no render_ms (a build from before gan-avatar's was recorded)"
    return f


def main(argv):
    args = parse_args(argv)
    deadline = Deadline(args.deadline_minutes)
    args.out.mkdir(parents=True, exist_ok=True)
    args.work.mkdir(parents=True, exist_ok=True)
    report = {"version": REPORT_VERSION, "tool": "scripts/gpu_check.sh", "mode": args.kind + ("-tiny" * args.tiny),
              "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "deadline_minutes": args.deadline_minutes,
              "finished": False, "steps": []}
    manifest = read_json(args.packs / "manifest.json")
    report["packs"] = {"folder": str(args.packs), "manifest": manifest and {k: v for k, v in manifest.items()
                                                                           if k != "runs"}}
    runs = (manifest or {}).get("runs", [])
    minutes = {"gaussian_style_talking_static": args.gs_minutes, "gan_avatar_talking_static": args.gan_minutes}
    report["_runs"] = runs
    report["_minutes"] = {e["name"]: minutes.get(e["name"], args.grid_minutes if e["model"] == "gaussian-style"
                                                 else args.gan_minutes) for e in runs}
    # Each step adds its entry to report["steps"] before it can fail; the
    # report is written after every step, so that a call stopped at its
    # limit still leaves what was measured.
    def guarded(name, fn, *a):
        try:
            fn(*a)
        except Exception as e:
            report["steps"].append(step_result(name, error=f"{type(e).__name__}: {e}"))
        report["wall_seconds"] = round(deadline.elapsed_s(), 1)
        write_outputs(args, report)
    m = step_result("machine")
    report["steps"].append(m)
    t = time.monotonic()
    try:
        report["machine"] = machine(args)
        if not report["machine"].get("commit") and manifest:  # a copy of the tree without .git
            report["machine"]["commit"] = f"{manifest.get('commit')} (the packs')"
        m["ok"] = True
    except Exception as e:
        report["machine"] = {"device": args.device}
        m["error"] = f"{type(e).__name__}: {e}"
    m["seconds"] = round(time.monotonic() - t, 1)
    if args.kind == "cuda" and not args.no_build:
        guarded("build", build, args, deadline, report)
    else:
        b = step_result("build", ok=args.headforge_train.exists(), seconds=0.0, build_dir=str(args.build_dir),
                        skipped="the programs of the build folder, as built")
        if not b["ok"]:
            b["error"] = "no headforge-train at " + str(args.headforge_train)
        report["steps"].append(b)
    guarded("rasterizer", rasterizer, args, report)
    if manifest is None:
        report["steps"].append(step_result("packs", error=f"no manifest.json in {args.packs} (make it with "
                                                          "scripts/gpu_check.sh --prepare)"))
    for entry in runs:
        guarded(entry["name"], train, args, entry, report["_minutes"][entry["name"]], deadline, report)
    # The GPU tests last, in what time is left: the figures come first.
    if args.kind == "cuda" and not args.no_cuda_tests:
        guarded("cuda_tests", cuda_tests, args, deadline, report)
    report["not_measured"] = [
        {"name": "nccl_one_rank", "why": "the distributed training (one rank over NCCL) is not in this tree yet"},
        {"name": "blendshape_render", "why": "the linear blendshape model is not in this tree yet"}]
    report["wall_seconds"] = round(deadline.elapsed_s(), 1)
    report["ok"] = all(s["ok"] for s in report["steps"])
    report["finished"] = True
    write_outputs(args, report)
    print(gpu_table.markdown(report))
    print(f"gpu_check: {sum(s['ok'] for s in report['steps'])} of {len(report['steps'])} steps ok in "
          f"{report['wall_seconds']:.0f} s; {args.out / 'gpu_check.json'}", file=sys.stderr)
    return 0 if report["ok"] else 1


def write_outputs(args, report):
    shown = {k: v for k, v in report.items() if not k.startswith("_")}
    (args.out / "gpu_check.json").write_text(json.dumps(shown, indent=1, default=str) + "\n")
    (args.out / "gpu_check.md").write_text(gpu_table.markdown(shown))
    # The logs and each model's small files, for what the JSON leaves out.
    with tarfile.open(args.out / "gpu_check_logs.tar.gz", "w:gz") as tar:
        logs = args.work / "logs"
        if logs.exists():
            tar.add(logs, arcname="logs")
        for model in sorted((args.work / "models").glob("*")):
            for name in ("eval.json", "config.json", "stats.jsonl"):
                if (model / name).exists():
                    tar.add(model / name, arcname=f"models/{model.name}/{name}")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
