#!/usr/bin/env python3
"""gpu_check.json (scripts/gpu_check.sh's report) as the markdown that
docs/benchmarks' GPU tables take: the machine (card, driver, PyTorch), one
row per training, the rasterizer at its size, and every step that failed.
  python3 scripts/gpu_table.py gpu_check.json [> table.md]
Python 3 standard library only."""
import json
import math
import sys


def _num(x, fmt):
    return fmt.format(x) if isinstance(x, (int, float)) and math.isfinite(x) else "–"


def _ms(x):
    if not isinstance(x, (int, float)) or not math.isfinite(x):
        return "–"
    return f"{x:.1f} ms" if x < 10 else f"{x:.0f} ms"


def machine_line(report):
    m = report.get("machine", {})
    if m.get("card"):
        what = f"{m['card']} (driver {m.get('driver') or '?'})"
    else:
        what = f"{m.get('cores', '?')} CPU cores ({m.get('cpu') or 'unknown CPU'})"
    torch = m.get("torch") or "?"
    if m.get("torch_cuda"):
        torch += f", CUDA {m['torch_cuda']}"
    parts = [what, f"PyTorch {torch}"]
    if m.get("nvcc"):
        parts.append(m["nvcc"])
    parts.append(f"commit {m.get('commit') or '?'}")
    parts.append(report.get("started", "")[:10])
    return "; ".join(p for p in parts if p)


def markdown(report):
    lines = [f"GPU check ({report.get('mode')}): {machine_line(report)}; "
             f"{_num(report.get('wall_seconds'), '{:.0f}')} s in all.", ""]
    steps = report.get("steps", [])
    trainings = [s for s in steps if "model" in s]
    if trainings:
        lines += ["| run | pack | minutes | steps | step time | held-out PSNR / SSIM, head | frame | "
                  "training views, head | render | peak memory |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for s in trainings:
            size = f" at {s['render_size']}" if s.get("render_size") else ""
            render = f"{_ms(s.get('render_ms'))} ({_num(s.get('render_fps'), '{:.0f}')} frames/s{size})" \
                if s.get("render_ms") else "–"
            peak = _num(s.get("peak_memory_mib"), "{:.0f} MiB")
            steps_cell = _num(s.get("steps"), "{:d}")
            if s.get("gaussians"):
                steps_cell += f" ({s['gaussians']:,} Gaussians)".replace(",", " ")
            lines.append(
                f"| {s['model']} `{s.get('preset') or '?'}`, {s.get('capture') or s['name']} | "
                f"{_num(s.get('pack_mib'), '{:.0f} MiB')} ({_num(s.get('pack_xz_mib'), '{:.1f}')} as xz) | "
                f"{_num(s.get('minutes'), '{:.2g}')} | {steps_cell} | "
                f"{_ms(s.get('step_ms'))} | {_num(s.get('psnr_head'), '{:.2f}')} dB / "
                f"{_num(s.get('ssim_head'), '{:.3f}')} | {_num(s.get('psnr_frame'), '{:.2f}')} dB / "
                f"{_num(s.get('ssim_frame'), '{:.3f}')} | {_num(s.get('psnr_training_views'), '{:.2f}')} dB | "
                f"{render} | {peak} |")
        lines.append("")
    raster = next((s for s in steps if s["name"] == "rasterizer"), None)
    if raster and raster.get("results"):
        lines += ["| C | N | image | forward | backward | forward + backward | peak memory |",
                  "|---|---|---|---|---|---|---|"]
        for r in raster["results"]:
            lines.append(f"| {r['channels']} | {r['gaussians'] // 1000}k | {r['side']}² | "
                         f"{_ms(r.get('forward_ms'))} | {_ms(r.get('backward_ms'))} | "
                         f"{_ms(r.get('forward_backward_ms'))} | {_num(r.get('peak_mib'), '{:.0f} MiB')} |")
        lines.append("")
    tests = next((s for s in steps if s["name"] == "cuda_tests"), None)
    if tests and tests.get("ok"):
        lines += [f"avatar_cuda_test: {tests.get('passed')} passed.", ""]
    failed = [s for s in steps if not s.get("ok")]
    for s in failed:
        error = " ".join(str(s.get("error") or "failed").split())
        lines.append(f"- **{s['name']}** failed: {error[:300]}")
    for s in report.get("not_measured", []):
        lines.append(f"- not measured: {s['name']} ({s['why']})")
    return "\n".join(lines).rstrip() + "\n"


def main(argv):
    if len(argv) != 1 or argv[0] in ("-h", "--help"):
        print(__doc__.strip(), file=sys.stderr)
        return 2
    with open(argv[0]) as f:
        report = json.load(f)
    sys.stdout.write(markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
