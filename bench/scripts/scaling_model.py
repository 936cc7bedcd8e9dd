#!/usr/bin/env python3
"""The scaling model of docs/scaling.md: per-stage costs measured in a `tessera render
--stats` file, and from them the frame time of a large wall driven by N render nodes.

    python3 bench/scripts/scaling_model.py s.jsonl --model-triangles 871414 [--view-triangles 1e8]
        [--displays 64 --display-size 3840x2160] [--nodes 16,64,256,1024] [--link-gbps 100]
        [--gpu-triangles-per-s 0]

Measured (from the stats file; medians over the frames after the first):
  sort      rank 0's sort time per triangle of the model
  decode    a worker's decode CPU time per triangle it decodes (summed over its tiles)
  render    a worker's upload + draw time per triangle it draws (lavapipe here)
  readback  a worker's readback time per pixel it renders
  blit      rank 0's composite time per frame pixel
  png       rank 0's write time per frame pixel (PNG, fast deflate)
Assumed (flags, printed as such): the link bandwidth, and optionally a GPU's triangle
rate in place of the measured lavapipe one.

The model, for a frame of P pixels on D displays, T triangles in view, N render nodes,
frames pipelined (the period is the slowest stage's time):
  sort stage     T * sort / K                               (rank 0 and K-1 sorter ranks)
  render stage   dup * T / N * (decode + render) + P / N * (readback + 4 B / link)
  display stage  P / D * (4 B / link + blit + png)          (one display rank per display)
where dup is the measured ratio of triangles decoded over the tiles to triangles in view
(triangles on tile borders go to every tile they touch). Standard library only.
"""

import argparse
import json
import math
import statistics
import sys


def parse_size(s):
    w, h = s.lower().split("x")
    return int(w), int(h)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("stats")
    p.add_argument("--model-triangles", type=float, required=True, help="triangles of the measured model")
    p.add_argument("--frame-size", default="1920x1080", help="frame of the measured run")
    p.add_argument("--view-triangles", type=float, default=1e8, help="triangles in view in the predicted frame")
    p.add_argument("--displays", type=int, default=64)
    p.add_argument("--display-size", default="3840x2160")
    p.add_argument("--nodes", default="16,64,256,1024")
    p.add_argument("--link-gbps", type=float, default=100.0, help="assumed: each node's link, Gbit/s")
    p.add_argument("--gpu-triangles-per-s", type=float, default=0.0,
                   help="assumed: a GPU's draw rate, replacing the measured render cost (0: measured)")
    a = p.parse_args()

    lines = []
    with open(a.stats) as f:
        for i, text in enumerate(f):
            if text.strip():
                try:
                    lines.append(json.loads(text))
                except json.JSONDecodeError as e:
                    sys.exit(f"error: {a.stats}: line {i + 1}: not JSON ({e})")
    master = [l for l in lines if l.get("rank") == 0 and l.get("frame", 0) > 0]
    workers = [l for l in lines if l.get("rank", 0) != 0 and l.get("frame", 0) > 0]
    if not master or not workers:
        sys.exit(f"error: {a.stats}: needs at least two frames of rank 0 and worker lines")
    med = statistics.median
    fw, fh = parse_size(a.frame_size)
    frame_px = fw * fh

    # Per frame: triangles decoded over all tiles, and pixels rendered.
    sort = med(l["sort_ms"] for l in master) / a.model_triangles
    decoded = {l["frame"]: sum(t["triangles"] for t in l["tiles"]) for l in master}
    per_frame = {}
    for l in workers:
        s = per_frame.setdefault(l["frame"], {"decode": 0.0, "render": 0.0, "readback": 0.0})
        s["decode"] += l["decode_ms"]
        s["render"] += l["upload_ms"] + l["render_ms"]
        s["readback"] += l["readback_ms"]
    frames = sorted(set(decoded) & set(per_frame))
    decode = med(per_frame[k]["decode"] / max(decoded[k], 1) for k in frames)
    render = med(per_frame[k]["render"] / max(decoded[k], 1) for k in frames)
    readback = med(per_frame[k]["readback"] / frame_px for k in frames)
    dup = med(decoded[k] for k in frames) / a.model_triangles
    blit = med(l["composite_ms"] for l in master) / frame_px
    png = med(l["write_ms"] for l in master) / frame_px
    period = med(l["frame_ms"] for l in master)

    ns = 1e6  # ms -> ns
    print(f"measured in {a.stats} ({len(frames)} frames, {fw}x{fh}, model {a.model_triangles:,.0f} triangles):")
    print(f"  frame period {period:.1f} ms")
    print(f"  sort      {sort * ns:8.2f} ns per model triangle")
    print(f"  decode    {decode * ns:8.2f} ns per decoded triangle (CPU time)")
    print(f"  render    {render * ns:8.2f} ns per drawn triangle (upload + draw, this machine's renderer)")
    print(f"  readback  {readback * ns:8.3f} ns per pixel")
    print(f"  blit      {blit * ns:8.3f} ns per pixel")
    print(f"  png       {png * ns:8.3f} ns per pixel")
    print(f"  dup       {dup:8.3f} triangles decoded per triangle in view")
    link = 8.0 / (a.link_gbps * 1e9) * 1e3  # ms per byte
    print(f"assumed: link {a.link_gbps:g} Gbit/s ({4 * link * ns:.3f} ns per RGBA pixel)", end="")
    if a.gpu_triangles_per_s > 0:
        render = 1e3 / a.gpu_triangles_per_s
        print(f"; GPU draws {a.gpu_triangles_per_s:.3g} triangles/s ({render * ns:.3f} ns each)")
    else:
        print()

    dw, dh = parse_size(a.display_size)
    P = a.displays * dw * dh
    T = a.view_triangles
    print(f"\nwall: {a.displays} displays of {dw}x{dh} ({P / 1e6:.0f} Mpixel), {T:.3g} triangles in view")
    print(f"{'nodes':>6} {'sort ms':>9} {'render ms':>10} {'display ms':>11} {'period ms':>10} {'fps':>6}  slowest"
          f"  {'sorters':>8} {'period ms':>10} {'fps':>6}")
    sort_stage = T * sort
    display_stage = P / a.displays * (4 * link + blit + png)
    display_scanout = P / a.displays * (4 * link + blit)
    for n in [int(x) for x in a.nodes.split(",")]:
        render_stage = dup * T / n * (decode + render) + P / n * (readback + 4 * link)
        stages = {"sort": sort_stage, "render": render_stage, "display": display_stage}
        slowest = max(stages, key=stages.get)
        t = stages[slowest]
        # With --sorters K the sort divides K ways: the K that takes it off the critical path.
        rest = max(render_stage, display_stage)
        k = max(1, math.ceil(sort_stage / rest))
        tk = max(sort_stage / k, rest)
        print(f"{n:>6} {sort_stage:9.1f} {render_stage:10.1f} {display_stage:11.1f} {t:10.1f} {1e3 / t:6.2f}  {slowest:7}"
              f"  {k:>8} {tk:10.1f} {1e3 / tk:6.2f}")
    print(f"(display stage without PNG, scanning out: {display_scanout:.1f} ms)")


if __name__ == "__main__":
    main()
