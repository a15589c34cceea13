"""Makes the Draco glTF test files in tests/data/draco with Blender run headless (bpy).

    python tools/draco/make_fixtures.py OUT_DIR

Needs `pip install bpy==5.0.*` (Python 3.11; Blender's glTF exporter bundles the Draco
encoder). Writes a UV sphere (16 segments, 8 rings, radius 0.5) and a 4 x 4 grid with UVs
beside it, twice: uvs_draco.glb with KHR_draco_mesh_compression (the exporter's defaults:
compression level 6, positions quantized to 14 bits, normals 10, UVs 12) and uvs_plain.glb
without, the reference the decoded file is compared with.
"""

import os
import sys

import bpy


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=0.5)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4, size=1, location=(1.5, 0, 0), calc_uvs=True)
    for name, draco in [("uvs_draco.glb", True), ("uvs_plain.glb", False)]:
        result = bpy.ops.export_scene.gltf(
            filepath=os.path.join(out, name), export_format="GLB", export_materials="NONE",
            export_draco_mesh_compression_enable=draco,
        )
        assert result == {"FINISHED"}, result


if __name__ == "__main__":
    main()
