"""Imports werkstatt's exports into Blender (bpy, headless) and prints what Blender made of each:
one line per file, `<file> <triangles> <min x y z> <max x y z>`, in werkstatt's axes (Y up;
Blender imports Y-up glTF and USD as Z up, (x, y, z) to (x, -z, y), and this turns it back).

    python tools/usd/import_check.py FILE.glb FILE.usda ...

Used by the test formats::blender_imports_the_glb_and_usda_exports (WERKSTATT_BPY=python).
"""

import sys

import bpy


def check(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if path.endswith(".glb") or path.endswith(".gltf"):
        result = bpy.ops.import_scene.gltf(filepath=path)
    else:
        result = bpy.ops.wm.usd_import(filepath=path)
    assert result == {"FINISHED"}, result
    scene = bpy.context.scene
    scene.frame_set(scene.frame_start)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    triangles, lo, hi = 0, [float("inf")] * 3, [float("-inf")] * 3
    for obj in scene.objects:
        if obj.type != "MESH":
            continue
        evaluated = obj.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        triangles += sum(len(p.vertices) - 2 for p in mesh.polygons)
        for v in mesh.vertices:
            x, y, z = evaluated.matrix_world @ v.co
            p = (x, z, -y)
            lo = [min(a, b) for a, b in zip(lo, p)]
            hi = [max(a, b) for a, b in zip(hi, p)]
        evaluated.to_mesh_clear()
    print(path, triangles, *("%.6f" % c for c in lo + hi))


for path in sys.argv[1:]:
    check(path)
