"""Makes the Alembic test fixtures in tests/data/alembic with Blender run headless (bpy).

    python tools/alembic/make_fixtures.py OUT_DIR            # the committed fixtures
    python tools/alembic/make_fixtures.py OUT_DIR --big      # a 300-frame, ~20k-vertex cache (benchmark)

Needs `pip install bpy==5.0.*` (Python 3.11). Writes:
- cloth.abc: a 16x16-quad cloth (`Cloth`) falling onto a sphere (`Collider`), frames 1-8 at
  24 fps, with UVs and normals; two objects, the cloth animated, the sphere constant.
- cloth_obj/cloth_0001.obj ...: the same cloth alone as an OBJ sequence (Blender's OBJ exporter,
  Y up), the reference the .abc is compared against vertex by vertex.
- build.abc: a grid whose Build modifier adds faces frame by frame (changing topology).
With --big: big.abc and big_obj/ (not committed; docs/formats.md has the figures).
"""

import os
import sys

import bpy


def reset(frames):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, frames
    scene.render.fps = 24
    return scene


def select_only(*objects):
    bpy.ops.object.select_all(action="DESELECT")
    for o in objects:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]


def cloth_scene(subdivisions, frames):
    scene = reset(frames)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=0.6)
    sphere = bpy.context.object
    sphere.name = "Collider"
    sphere.modifiers.new("Collision", "COLLISION")
    bpy.ops.mesh.primitive_grid_add(
        x_subdivisions=subdivisions, y_subdivisions=subdivisions, size=2, location=(0, 0, 0.8), calc_uvs=True
    )
    cloth = bpy.context.object
    cloth.name = "Cloth"
    mod = cloth.modifiers.new("Cloth", "CLOTH")
    mod.point_cache.frame_start, mod.point_cache.frame_end = 1, frames
    # Step the simulation so the cache is baked before either exporter evaluates it.
    for f in range(1, frames + 1):
        scene.frame_set(f)
    scene.frame_set(1)
    return cloth, sphere


def export(out, name, cloth, sphere, frames):
    select_only(cloth, sphere)
    bpy.ops.wm.alembic_export(
        filepath=os.path.join(out, f"{name}.abc"), start=1, end=frames, uvs=True, normals=True,
        face_sets=False, evaluation_mode="RENDER", as_background_job=False,
    )
    obj_dir = os.path.join(out, f"{name}_obj")
    os.makedirs(obj_dir, exist_ok=True)
    select_only(cloth)
    bpy.ops.wm.obj_export(
        filepath=os.path.join(obj_dir, f"{name}.obj"), export_selected_objects=True, export_animation=True,
        start_frame=1, end_frame=frames, export_uv=True, export_normals=True, export_materials=False,
        apply_modifiers=True, forward_axis="NEGATIVE_Z", up_axis="Y",
    )


def build_scene(out):
    reset(5)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4, size=1, calc_uvs=True)
    grid = bpy.context.object
    grid.name = "Growing"
    build = grid.modifiers.new("Build", "BUILD")
    build.frame_start, build.frame_duration = 0, 5
    select_only(grid)
    bpy.ops.wm.alembic_export(
        filepath=os.path.join(out, "build.abc"), start=1, end=5, uvs=True, normals=True,
        face_sets=False, evaluation_mode="RENDER", as_background_job=False,
    )


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    if "--big" in sys.argv:
        # 141 x 141 quads: 20164 vertices; 300 frames.
        cloth, sphere = cloth_scene(141, 300)
        export(out, "big", cloth, sphere, 300)
        return
    cloth, sphere = cloth_scene(16, 8)
    export(out, "cloth", cloth, sphere, 8)
    build_scene(out)


if __name__ == "__main__":
    main()
