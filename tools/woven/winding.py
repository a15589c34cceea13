#!/usr/bin/env python3
"""Winding against normals in a `werkstatt fidelity export` scene.glb (numpy only).

For each mesh: the share of triangles whose winding normal (b - a) x (c - a) points along the
sum of their vertex normals ("outward", front face under wgpu's counter-clockwise default) or
against it. Back-face culling is only safe for meshes at 1.0000 outward.

    werkstatt fidelity export graphs/fig8_woven_lod.ron --out /tmp/glb
    python3 tools/woven/winding.py /tmp/glb/scene.glb
"""
import json
import struct
import sys

import numpy as np


def main(path):
    data = open(path, "rb").read()
    json_len = struct.unpack_from("<I", data, 12)[0]
    gltf = json.loads(data[20 : 20 + json_len])
    at = 20 + json_len
    bin_len = struct.unpack_from("<I", data, at)[0]
    blob = data[at + 8 : at + 8 + bin_len]

    def accessor(i):
        a = gltf["accessors"][i]
        view = gltf["bufferViews"][a["bufferView"]]
        offset = view.get("byteOffset", 0) + a.get("byteOffset", 0)
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
        dtype = {5126: np.float32, 5125: np.uint32, 5123: np.uint16}[a["componentType"]]
        out = np.frombuffer(blob, dtype=dtype, count=a["count"] * width, offset=offset)
        return out.reshape(-1, width) if width > 1 else out

    print("| mesh | triangles | outward | inward |\n|---|---:|---:|---:|")
    for k, mesh in enumerate(gltf["meshes"]):
        for prim in mesh["primitives"]:
            p = accessor(prim["attributes"]["POSITION"]).astype(np.float64)
            n = accessor(prim["attributes"]["NORMAL"]).astype(np.float64)
            tri = accessor(prim["indices"]).astype(np.int64).reshape(-1, 3)
            a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
            along = (np.cross(b - a, c - a) * n[tri].sum(axis=1)).sum(axis=1)
            out, inw = (along > 0).mean(), (along < 0).mean()
            print(f"| {mesh.get('name', k)} | {len(tri)} | {out:.4f} | {inw:.4f} |")


if __name__ == "__main__":
    main(sys.argv[1])
