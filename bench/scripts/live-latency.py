#!/usr/bin/env python3
"""Latency and frame rate of a live run, steered through its control port.

    bench/scripts/live-latency.py [--view | --present] [--wall WALL [--display-ranks D]]
                                  [--mpirun N] [--pixel-codec C] [--window-name REGEX]
                                  [--size 1280x720] [--tiles 4x4] [--steps 40] MODEL

Starts `tessera render MODEL --control` (or `tessera view`, under an Xvfb of its own, with
--view; `render --present` with --present, its windows on that Xvfb, one per display of
--wall, opened by D display ranks with --display-ranks D; under `mpirun -np N` with
--mpirun N), then:
  * latency: with windows, presses a key in the steering window with xdotool (A and D,
    flying left and right), else sends one `orbit` command at a time, and times it until the
    run's stats line of that frame comes back to a subscriber, which the writer sends as the
    frame is shown (in a window: as it is handed to the window; with display ranks: as rank 0
    sends the swap, after which each display rank draws its windows). Reports the median
    and the 95th percentile.
  * throughput: sends `orbit` commands as fast as the run takes them for 10 s (a drag's
    stream of moves, which the run joins into frames) and counts the frames shown a second.
  * idle: CPU seconds the run used over 5 s with nothing asked.
  * pixels: the tile pixels' bytes a frame as the workers sent them (`--pixel-codec`), and raw.
Uses the release binary (cargo build --release -p tessera).
"""
import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import time

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
BIN = os.path.join(ROOT, "target", "release", "tessera")


def cpu_seconds(pid):
    """User and system CPU seconds of a process and its children that were waited for."""
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def tree_cpu(pid):
    """CPU seconds of `pid` and every process below it (mpirun's ranks)."""
    total = 0.0
    for p in os.listdir("/proc"):
        if not p.isdigit():
            continue
        try:
            stat = open(f"/proc/{p}/stat").read()
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
        except OSError:
            continue
        if int(p) == pid or ppid == pid:
            total += cpu_seconds(int(p))
            if int(p) != pid:
                total += tree_cpu(int(p)) - cpu_seconds(int(p))
    return total


class Client:
    def __init__(self, addr):
        host, port = addr.rsplit(":", 1)
        self.sock = socket.create_connection((host, int(port)))
        self.lines = self.sock.makefile("r")

    def send(self, cmd):
        self.sock.sendall((json.dumps(cmd) + "\n").encode())

    def read(self):
        return json.loads(self.lines.readline())

    def ask(self, cmd):
        self.send(cmd)
        return self.read()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("model")
    ap.add_argument("--view", action="store_true")
    ap.add_argument("--present", action="store_true")
    ap.add_argument("--wall")
    ap.add_argument("--display-ranks", type=int, default=0)
    ap.add_argument("--pixel-codec", default="raw")
    ap.add_argument("--window-name", default="^Tessera", help="the steering window's title (a regex)")
    ap.add_argument("--mpirun", type=int, default=0)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--tiles", default="4x4")
    ap.add_argument("--steps", type=int, default=40)
    a = ap.parse_args()
    env = dict(os.environ, XDG_RUNTIME_DIR=os.environ.get("XDG_RUNTIME_DIR", "/tmp/tessera-xdg"))
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    xvfb = None
    windowed = a.view or a.present
    if windowed:
        display = f":{200 + os.getpid() % 300}"
        xvfb = subprocess.Popen(["Xvfb", display, "-screen", "0", "1920x1080x24", "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(1)
        env["DISPLAY"] = display
    cmd = [BIN, "view" if a.view else "render", a.model, "--size", a.size, "--tiles", a.tiles,
           "--control", "127.0.0.1:0", "--pixel-codec", a.pixel_codec]
    if a.present:
        cmd += ["--present"]
    if a.wall:
        cmd += ["--wall", a.wall]
    if a.display_ranks:
        cmd += ["--display-ranks", str(a.display_ranks)]
    if a.mpirun:
        cmd = ["mpirun", "--oversubscribe", "--bind-to", "none", "-np", str(a.mpirun), "-x", "DISPLAY"] + cmd
    run = subprocess.Popen(cmd, env=env, stderr=subprocess.PIPE, text=True)
    addr = None
    for line in run.stderr:
        if line.startswith("tessera: control port on "):
            addr = line.split()[-1]
            break
    if addr is None:
        sys.exit("the run ended before its control port opened")
    c, stats = Client(addr), Client(addr)
    stats.ask({"cmd": "subscribe"})

    def shown(k):
        while True:
            line = stats.read()
            if line.get("frame") == k:
                return line

    # The first frame, shown.
    while c.ask({"cmd": "status"})["frames"] < 1:
        time.sleep(0.05)
    pixels = [shown(0)]
    window = None
    if windowed:
        x = lambda *args: subprocess.run(["xdotool", *args], env=env, check=True, capture_output=True,
                                          text=True).stdout.split()
        window = x("search", "--sync", "--name", a.window_name)[0]
        x("windowfocus", "--sync", window)
    latencies = []
    for i in range(a.steps):
        t0 = time.perf_counter()
        if window:
            frames = c.ask({"cmd": "status"})["frames"]
            t0 = time.perf_counter()
            x("key", "--window", window, "a" if i % 2 else "d")
            pixels.append(shown(frames))
        else:
            k = c.ask({"cmd": "orbit", "degrees": 3})["frame"]
            pixels.append(shown(k))
        latencies.append((time.perf_counter() - t0) * 1e3)
    latencies.sort()
    p95 = latencies[min(len(latencies) - 1, int(round(0.95 * (len(latencies) - 1))))]
    # Throughput: commands as fast as they are taken, frames counted on the subscriber.
    first = c.ask({"cmd": "status"})["frames"]
    t0 = time.perf_counter()
    last = first
    while time.perf_counter() - t0 < 10:
        last = c.ask({"cmd": "orbit", "degrees": 1})["frame"]
    shown(last)
    seconds = time.perf_counter() - t0
    fps = (last - first + 1) / seconds
    # Idle.
    time.sleep(1)
    before = tree_cpu(run.pid)
    time.sleep(5)
    idle = tree_cpu(run.pid) - before
    c.ask({"cmd": "quit"})
    run.wait(timeout=60)
    if xvfb:
        xvfb.kill()
    what = "view" if a.view else "render --present" if a.present else "render --control"
    what += f" --wall {os.path.basename(a.wall)}" if a.wall else ""
    what += f" --display-ranks {a.display_ranks}" if a.display_ranks else ""
    what += f" under mpirun -np {a.mpirun}" if a.mpirun else " alone"
    coded = statistics.median(p.get("pixel_coded_bytes", 0) for p in pixels)
    raw = statistics.median(p.get("pixel_raw_bytes", 0) for p in pixels)
    encode = statistics.median(p.get("pixel_encode_ms", 0) for p in pixels)
    decode = statistics.median(p.get("pixel_decode_ms", 0) + (p.get("displays") or {}).get("pixel_decode_ms", 0)
                               for p in pixels)
    size = "the wall's frame" if a.wall else a.size
    print(f"{what}, {os.path.basename(a.model)}, {size}, {a.tiles} tiles:")
    how = "key press in the window" if window else "command"
    print(f"  {how} to frame shown: median {statistics.median(latencies):.0f} ms, 95th percentile {p95:.0f} ms "
          f"({a.steps} steps)")
    print(f"  steered continuously: {fps:.1f} frames shown a second")
    print(f"  idle: {idle:.2f} CPU s over 5 s")
    print(f"  pixels ({a.pixel_codec}): {coded / 1e3:.0f} kB a frame sent, {raw / 1e3:.0f} kB raw "
          f"({raw / max(coded, 1):.1f}x); coded in {encode:.1f} ms (the workers' tiles summed), decoded in "
          f"{decode:.1f} ms")


if __name__ == "__main__":
    main()
