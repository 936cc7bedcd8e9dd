#!/usr/bin/env python3
"""Writes handmade.gltf (buffers embedded as a data URI) and handmade.glb: every case of
the glTF loader the peer tools do not write. Prints the expected world-space triangles.

- node hierarchy: node 0 (translation 10 0 0) > node 1 (scale 2) > mesh 0;
- node 2 (rotation 90 degrees about z) > mesh 1; node 4 (scale -1 1 1, a mirror) > mesh 2;
- node 3 holds mesh 0 but is in no scene: not loaded;
- mesh 0: TRIANGLES indexed with u16, TRIANGLE_STRIP with u8, TRIANGLE_FAN with u32,
  all on one position accessor with NORMAL and COLOR_0 (u8 normalized RGBA);
- mesh 1: TRIANGLES without indices, TRIANGLES on a sparse position accessor (vertex 2
  moved to 2 2 0), and LINES (skipped, counted);
- mesh 2: one triangle under the mirror (its winding flips).
"""
import base64, json, math, struct

buf = bytearray()
views = []
def view(data, target=None):
    while len(buf) % 4:
        buf.append(0)
    off = len(buf)
    buf.extend(data)
    v = {"buffer": 0, "byteOffset": off, "byteLength": len(data)}
    if target:
        v["target"] = target
    views.append(v)
    return len(views) - 1

acc = []
def accessor(**a):
    acc.append(a)
    return len(acc) - 1

square = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
pv = view(b"".join(struct.pack("<3f", *p) for p in square), 34962)
pos = accessor(bufferView=pv, componentType=5126, count=4, type="VEC3", min=[0, 0, 0], max=[1, 1, 0])
nv = view(b"".join(struct.pack("<3f", 0, 0, 1) for _ in square), 34962)
nrm = accessor(bufferView=nv, componentType=5126, count=4, type="VEC3")
cv = view(bytes([255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 128]), 34962)
col = accessor(bufferView=cv, componentType=5121, normalized=True, count=4, type="VEC4")
i16 = accessor(bufferView=view(struct.pack("<6H", 0, 1, 2, 0, 2, 3), 34963), componentType=5123, count=6, type="SCALAR")
i8 = accessor(bufferView=view(bytes([0, 1, 3, 2]), 34963), componentType=5121, count=4, type="SCALAR")
i32 = accessor(bufferView=view(struct.pack("<4I", 0, 1, 2, 3), 34963), componentType=5125, count=4, type="SCALAR")
tri = [(0, 0, 1), (1, 0, 1), (0, 1, 1)]
bpos = accessor(bufferView=view(b"".join(struct.pack("<3f", *p) for p in tri), 34962), componentType=5126, count=3,
                type="VEC3", min=[0, 0, 1], max=[1, 1, 1])
sparse = accessor(bufferView=pv, componentType=5126, count=4, type="VEC3", min=[0, 0, 0], max=[2, 2, 0],
                  sparse={"count": 1,
                          "indices": {"bufferView": view(struct.pack("<H", 2)), "componentType": 5123},
                          "values": {"bufferView": view(struct.pack("<3f", 2, 2, 0))}})
i3 = accessor(bufferView=view(struct.pack("<3H", 0, 1, 2), 34963), componentType=5123, count=3, type="SCALAR")
lines = accessor(bufferView=view(struct.pack("<2H", 0, 1), 34963), componentType=5123, count=2, type="SCALAR")

attrs = {"POSITION": pos, "NORMAL": nrm, "COLOR_0": col}
doc = {
    "asset": {"version": "2.0", "generator": "tessera make_handmade.py"},
    "scene": 0,
    "scenes": [{"nodes": [0, 2, 4]}],
    "nodes": [
        {"translation": [10, 0, 0], "children": [1]},
        {"scale": [2, 2, 2], "mesh": 0},
        {"rotation": [0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)], "mesh": 1},
        {"mesh": 0},
        {"scale": [-1, 1, 1], "mesh": 2},
    ],
    "meshes": [
        {"primitives": [{"attributes": attrs, "indices": i16, "mode": 4},
                        {"attributes": attrs, "indices": i8, "mode": 5},
                        {"attributes": attrs, "indices": i32, "mode": 6}]},
        {"primitives": [{"attributes": {"POSITION": bpos}},
                        {"attributes": {"POSITION": sparse}, "indices": i3, "mode": 4},
                        {"attributes": {"POSITION": pos}, "indices": lines, "mode": 1}]},
        {"primitives": [{"attributes": {"POSITION": pos}, "indices": i3}]},
    ],
    "accessors": acc,
    "bufferViews": views,
}
while len(buf) % 4:
    buf.append(0)
embedded = dict(doc, buffers=[{"byteLength": len(buf),
                               "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(buf)).decode()}])
open("handmade.gltf", "w").write(json.dumps(embedded, indent=1))
js = json.dumps(dict(doc, buffers=[{"byteLength": len(buf)}])).encode()
while len(js) % 4:
    js += b" "
glb = struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(js) + 8 + len(buf))
glb += struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(buf), 0x004E4942) + bytes(buf)
open("handmade.glb", "wb").write(glb)
