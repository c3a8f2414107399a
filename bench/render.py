"""Renderer benchmark (issue: point-cloud renderer): seconds, points/s and coverage for scale x point
size (fixed disks, and world splats with the gap fill) on a dense synthetic scene, beside a
straightforward numpy z-buffer measured in the same run.

    python bench/render.py [--points 12000000] [--device cpu|cuda] [--memory-points 50000000]

The camera is the paper's undistorted Zenmuse frame (5645 x 4082, fx 4000) looking at the scene; the
scene is a ground plane with boxes sampled so that the view sees ``--points`` points. The memory check
renders ``--memory-points`` points in a subprocess and prints its peak resident memory.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time

import numpy as np
import torch

from siteline.camera.pinhole import Camera
from siteline.records.params.render import RenderParams
from siteline.render.zbuffer import render_points

W, H, FX = 5645, 4082, 4000.0
ALT_M = 80.0


def scene(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Ground plus 40 boxes filling the nadir view from 80 m: (n, 3) float32, (n, 3) uint8."""
    rng = np.random.default_rng(seed)
    half_w, half_h = W / 2 * ALT_M / FX, H / 2 * ALT_M / FX
    xyz = np.empty((n, 3), np.float32)
    n_ground = int(n * 0.7)
    xyz[:n_ground, 0] = rng.uniform(-half_w, half_w, n_ground)
    xyz[:n_ground, 1] = rng.uniform(-half_h, half_h, n_ground)
    xyz[:n_ground, 2] = rng.normal(0, 0.02, n_ground)
    k = n - n_ground
    centers = rng.uniform([-half_w * 0.8, -half_h * 0.8], [half_w * 0.8, half_h * 0.8], (40, 2))
    sizes = rng.uniform(3, 12, (40, 3))
    which = rng.integers(0, 40, k)
    u = rng.uniform(-0.5, 0.5, (k, 3))
    xyz[n_ground:, :2] = centers[which] + u[:, :2] * sizes[which, :2]
    xyz[n_ground:, 2] = (u[:, 2] + 0.5) * sizes[which, 2]
    rgb = rng.integers(0, 256, (n, 3), dtype=np.uint8)
    return xyz, rgb


def numpy_zbuffer(xyz: np.ndarray, cam: Camera) -> np.ndarray:
    """The baseline: project in numpy, sort by (pixel, depth) with np.lexsort, keep the first per pixel."""
    c = xyz @ cam.R.T.astype(np.float32) + cam.t.astype(np.float32)
    z = c[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = c[:, 0] / z * cam.fx + cam.cx
        v = c[:, 1] / z * cam.fy + cam.cy
    ok = (z > 1e-3) & (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height)
    idx = np.nonzero(ok)[0]
    pix = v[ok].astype(np.int64) * cam.width + u[ok].astype(np.int64)
    order = np.lexsort((idx, z[ok], pix))
    first = np.r_[True, pix[order][1:] != pix[order][:-1]]
    out = np.full(cam.width * cam.height, -1, np.int64)
    out[pix[order][first]] = idx[order][first]
    return out.reshape(cam.height, cam.width)


def timed(fn, repeats: int = 2) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        if torch.cuda.is_available():
            torch.cuda.synchronize()
        best = min(best, time.perf_counter() - t)
    return best, out


def rss_mib() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * resource.getpagesize() / 2**20


def memory_child(n: int, scale: float) -> None:
    """Render n points from a generated array; print the resident memory sampled during the render."""
    import threading

    xyz, rgb = scene(n, seed=1)
    cam = Camera.look_at((0, 0, ALT_M), (0, 0, 0), W, H, FX)
    before = rss_mib()
    peak = [before]
    done = threading.Event()

    def sample() -> None:
        while not done.is_set():
            peak[0] = max(peak[0], rss_mib())
            time.sleep(0.002)

    th = threading.Thread(target=sample)
    th.start()
    t = time.perf_counter()
    render_points(xyz, cam, RenderParams(scale=scale), {"rgb": rgb})
    done.set()
    th.join()
    input_mib = (xyz.nbytes + rgb.nbytes) / 2**20
    print(
        f"memory: {n / 1e6:.0f}M points rendered at scale {scale:g} in {time.perf_counter() - t:.1f} s; "
        f"input arrays {input_mib:.0f} MiB; process RSS before {before:.0f} MiB, peak during render "
        f"{peak[0]:.0f} MiB (renderer's own: {peak[0] - before:.0f} MiB)"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=12_000_000)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--memory-points", type=int, default=50_000_000)
    ap.add_argument("--memory-child", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--memory-scale", type=float, default=0.125, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.memory_child:
        memory_child(args.memory_child, args.memory_scale)
        return
    print(f"torch {torch.__version__}, threads {torch.get_num_threads()}, device {args.device}")
    xyz, rgb = scene(args.points)
    if args.device != "cpu":
        # measure the renderer, not the host-to-device copy: the points already live on the device
        xyz, rgb = torch.from_numpy(xyz).to(args.device), torch.from_numpy(rgb).to(args.device)
    cam = Camera.look_at((0, 0, ALT_M), (0, 0, 0), W, H, FX)
    # the scene's spacing: 70 % of the points on the ground the view covers (world splats' input)
    spacing_m = np.float32(1.0 / np.sqrt(0.7 * args.points / ((W * ALT_M / FX) * (H * ALT_M / FX))))
    spacing = torch.full((args.points,), float(spacing_m), device=args.device)
    rows = []
    for scale in (1.0, 0.5, 0.25, 0.125):
        for ps, splat in ((1, "fixed"), (3, "fixed"), (1, "world")):
            s = RenderParams(scale=scale, point_size_px=ps, splat=splat, fill_px=2 if splat == "world" else 0)
            render_points(xyz[:1000], cam, s, device=args.device, spacing_m=spacing[:1000])  # warm-up
            sec, r = timed(
                lambda s=s: render_points(xyz, cam, s, {"rgb": rgb}, device=args.device, spacing_m=spacing)
            )
            rows.append(
                (scale, ps, splat, sec, args.points / sec, r.coverage, r.camera.width, r.camera.height)
            )
    base = {}
    if args.device != "cpu":
        xyz, rgb = xyz.cpu().numpy(), rgb.cpu().numpy()
    for scale in (1.0, 0.125):
        sc = cam.scaled(scale)
        sec, idx = timed(lambda sc=sc: numpy_zbuffer(xyz, sc), repeats=1)
        base[scale] = sec
        ours = render_points(xyz, cam, RenderParams(scale=scale, precision="float32"), device=args.device)
        agree = (ours.index == idx).mean()
        print(
            f"numpy baseline at scale {scale}: {sec:.2f} s ({args.points / sec / 1e6:.1f} M points/s); "
            f"pixel agreement with siteline {agree:.4%}"
        )
    print()
    print(
        f"| scale | size (px) | point size | splats (spacing {spacing_m:.3f} m) | seconds | M points/s | coverage | speed-up vs numpy |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for scale, ps, splat, sec, pps, cov, w, h in rows:
        ratio = f"{base[scale] / sec:.1f}x" if scale in base and ps == 1 and splat == "fixed" else ""
        print(f"| {scale:g} | {w}x{h} | {ps} | {splat} | {sec:.3f} | {pps / 1e6:.1f} | {cov:.2%} | {ratio} |")
    if args.memory_points and args.device == "cpu":
        print()
        for scale in (0.125, 1.0):
            out = subprocess.run(
                [
                    sys.executable,
                    __file__,
                    "--memory-child",
                    str(args.memory_points),
                    "--memory-scale",
                    str(scale),
                ],
                capture_output=True,
                text=True,
                check=True,
            )
            print(out.stdout.strip())


if __name__ == "__main__":
    main()
