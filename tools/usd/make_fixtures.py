"""Makes the USD test fixtures in tests/data/usd with Blender run headless (bpy), from the same
cloth simulation as the Alembic fixtures (tools/alembic/make_fixtures.py).

    python tools/usd/make_fixtures.py OUT_DIR           # the committed fixtures
    python tools/usd/make_fixtures.py OUT_DIR --big     # a 300-frame, ~20k-vertex cache (benchmark)

Needs `pip install bpy==5.0.*` (Python 3.11). Writes:
- cloth.usdc: the 16x16-quad cloth (`/root/Cloth/Grid`) falling onto the sphere
  (`/root/Collider/Sphere`), frames 1-8 at 24 fps, with UVs and normals (face-varying), as
  Blender writes it by default: Z up, the objects' placements as Xform ops.
- cloth.usda: the cloth alone, the same frames, as text, turned to Y up by the exporter
  (forward -Z, up Y), without normals (to keep it small).
- build.usdc: the grid whose Build modifier adds faces frame by frame (changing topology).
The OBJ reference of the same simulation is tests/data/alembic/cloth_obj.
With --big: big.usdc and big.usda, and big.abc and big_obj/ of the same simulation (not
committed; docs/formats.md has the figures).
"""

import os
import sys

import bpy

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "alembic"))
import make_fixtures as abc  # noqa: E402


def usd_export(path, **options):
    result = bpy.ops.wm.usd_export(
        filepath=path, selected_objects_only=True, export_animation=True, export_uvmaps=True,
        export_materials=False, evaluation_mode="RENDER", **options,
    )
    assert result == {"FINISHED"}, result


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    if "--big" in sys.argv:
        # One simulation for every format: the Alembic script's big.abc and big_obj/ too.
        cloth, sphere = abc.cloth_scene(141, 300)
        abc.export(out, "big", cloth, sphere, 300)
        abc.select_only(cloth)
        usd_export(os.path.join(out, "big.usdc"), export_normals=True)
        usd_export(os.path.join(out, "big.usda"), export_normals=True)
        return
    cloth, sphere = abc.cloth_scene(16, 8)
    abc.select_only(cloth, sphere)
    usd_export(os.path.join(out, "cloth.usdc"), export_normals=True)
    abc.select_only(cloth)
    usd_export(
        os.path.join(out, "cloth.usda"), export_normals=False, convert_orientation=True,
        export_global_forward_selection="NEGATIVE_Z", export_global_up_selection="Y",
    )
    abc.reset(5)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4, size=1, calc_uvs=True)
    grid = bpy.context.object
    grid.name = "Growing"
    build = grid.modifiers.new("Build", "BUILD")
    build.frame_start, build.frame_duration = 0, 5
    abc.select_only(grid)
    usd_export(os.path.join(out, "build.usdc"), export_normals=True)


if __name__ == "__main__":
    main()
