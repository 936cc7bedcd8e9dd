#!/usr/bin/env python3
"""Converts an X screenshot (`xwd -root -silent`, 24-bit screen) to a PNG, with the standard
library only:

    xwd -root -silent | python3 scripts/dev/xwd-png.py OUT.png [X Y W H [WX,WY,WW,WH ...]]

cropped to X Y W H; given windows' rectangles, the screen outside them is drawn grey, so that
black windows show on Xvfb's black screen. The README's picture of a live wall is made this
way (scripts/dev/wall-screenshot.sh)."""
import struct
import sys
import zlib


def main():
    data = sys.stdin.buffer.read()
    f = lambda i: struct.unpack(">I", data[i * 4:i * 4 + 4])[0]
    header, width, height, lsb, bpp, bpl, colors = f(0), f(4), f(5), f(7) == 0, f(11), f(12), f(19)
    if bpp != 32:
        sys.exit(f"error: {bpp} bits a pixel; a 24-bit screen stores 32")
    x0, y0, w, h = (int(v) for v in sys.argv[2:6]) if len(sys.argv) >= 6 else (0, 0, width, height)
    windows = [tuple(int(v) for v in a.split(",")) for a in sys.argv[6:]]
    inside = lambda x, y: not windows or any(wx <= x < wx + ww and wy <= y < wy + wh for wx, wy, ww, wh in windows)
    start = header + colors * 12
    rows = []
    for y in range(y0, min(y0 + h, height)):
        row = bytearray(b"\0")
        for x in range(x0, min(x0 + w, width)):
            b = data[start + y * bpl + x * 4:start + y * bpl + x * 4 + 4]
            v = struct.unpack("<I" if lsb else ">I", b)[0] if inside(x, y) else 0x505050
            row += bytes(((v >> 16) & 255, (v >> 8) & 255, v & 255))
        rows.append(bytes(row))
    w, h = min(w, width - x0), len(rows)
    chunk = lambda kind, body: struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(b"".join(rows), 9)) + chunk(b"IEND", b"")
    with open(sys.argv[1], "wb") as out:
        out.write(png)


if __name__ == "__main__":
    main()
