#!/usr/bin/env python3
"""Per-stage times and the distribution overhead of a `tessera render --stats` run.

    python3 scripts/overhead.py stats.jsonl

Prints one line per frame (rank 0's sort, send and composite; the workers' decode, upload,
render and readback, summed over workers) and then the ranges and the overhead: sort + send +
composite against the workers' render time, per frame and over the whole run (not for a
`--decode-only` run, which renders nothing). Frames reused from the frame before (a still
camera: `"reused": true`, nothing sorted or rendered) are counted apart.
"""
import json
import sys


def main(path):
    frames = {}
    for line in open(path):
        d = json.loads(line)
        f = frames.setdefault(d["frame"], {"workers": []})
        if d["rank"] == 0:
            f["master"] = d
        else:
            f["workers"].append(d)
    rows = []
    reused = [k for k in frames if frames[k]["master"].get("reused")]
    for k in sorted(frames):
        if k in reused:
            continue
        m, ws = frames[k]["master"], frames[k]["workers"]
        row = {s: m[s] for s in ("sort_ms", "send_ms", "composite_ms")}
        for s in ("decode_ms", "upload_ms", "render_ms", "readback_ms"):
            row[s] = sum(w[s] for w in ws)
        row["tile_bytes"] = sum(t["bytes"] for t in m["tiles"])
        row["normal_bytes"] = sum(t["normal_bytes"] for t in m["tiles"])
        row["overhead"] = row["sort_ms"] + row["send_ms"] + row["composite_ms"]
        row["ratio"] = row["overhead"] / row["render_ms"] if row["render_ms"] > 0 else float("inf")
        rows.append(row)
        print(
            f"frame {k + 1:3}: sort {row['sort_ms']:6.1f} send {row['send_ms']:5.1f} composite {row['composite_ms']:4.1f}"
            f" | decode {row['decode_ms']:6.1f} upload {row['upload_ms']:5.1f} render {row['render_ms']:6.1f}"
            f" readback {row['readback_ms']:4.1f} | overhead/render {row['ratio']:.2f}"
        )
    if not rows:
        sys.exit(f"{path}: no frames")
    if reused:
        print(f"{len(reused)} of {len(frames)} frames reused from the frame before (a still view)")
    for s in ("sort_ms", "send_ms", "composite_ms", "decode_ms", "upload_ms", "render_ms", "readback_ms"):
        v = [r[s] for r in rows]
        print(f"{s[:-3]:>10}: {min(v):.1f}-{max(v):.1f} ms")
    tb = [r["tile_bytes"] for r in rows]
    nb = [r["normal_bytes"] for r in rows]
    print(f"tile bytes {min(tb)}-{max(tb)}, border normal bytes {min(nb)}-{max(nb)} per frame")
    rendered = sum(r["render_ms"] for r in rows)
    if rendered == 0:
        # `render --decode-only`: nothing was rasterized, so there is no ratio to give.
        print("no render time (a --decode-only run): the stage times above are the distribution alone")
        return
    ratios = [r["ratio"] for r in rows]
    total = sum(r["overhead"] for r in rows) / rendered
    over = sum(x > 0.5 for x in ratios)
    print(
        f"overhead/render: {min(ratios):.2f}-{max(ratios):.2f} per frame, {total:.2f} over the run;"
        f" {over} of {len(rows)} frames above 0.5"
    )


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
