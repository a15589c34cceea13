#!/usr/bin/env python3
"""Render a `werkstatt fidelity export` folder in Blender Cycles (docs/fidelity.md).

    python tools/fidelity/cycles.py DIR [--samples N] [--direct-only] [--out NAME] [--half]

Runs with a Python that has Blender's `bpy` module (pip install bpy==5.0.0, Python 3.11); without
it the script says so and exits with status 0 (skipped), so a pipeline without Blender goes on.

Reads DIR/scene.glb, DIR/scene.json and DIR/texture_<i>.png; writes DIR/cycles.exr (linear
radiance, RGBA float, ZIP; --half: half floats) and DIR/cycles.json (settings, timings and the
camera check: werkstatt's projections of the items' bounding-box corners against Blender's).

Conventions (scene.json `conventions`): werkstatt is Y up; glTF is Y up and Blender's importer
turns it to Z up, a werkstatt point (x, y, z) landing at Blender (x, -z, y). The camera is set
from eye, target and up in the same mapping, with the vertical field of view (sensor fit
vertical), the same aspect, and a box pixel filter 0.01 px wide: one sample position per pixel,
its centre, as the rasterizer and the ids sample. The probe is an equirectangular world texture
whose lookup direction is turned by -90 - rotation degrees about Blender's Z so that Blender's
equirect convention (u = 0.5 - atan2(d.y, d.x) / 2pi, the map's centre looking down +X) equals
werkstatt's (u = 0.5 + atan2(x, -z) / 2pi, the centre looking down -Z). Standard view transform, no look, exposure 0, no denoising, no sample clamping, no
glossy filter.

Materials: glossiness 0 is a Diffuse BSDF (Lambert) with the albedo; glossiness g > 0 is a
multiscatter GGX Glossy BSDF with the albedo as its colour and roughness sqrt(alpha), alpha =
sqrt(2 / (4 s + 2)) for werkstatt's Phong exponent s = 1 / (1 - g): werkstatt's lobe is cos^s
about the reflection, about a Blinn-Phong cos^(4 s) about the normal, and Blinn-Phong n is
Beckmann/GGX alpha^2 = 2 / (n + 2) (Walter et al. 2007); g = 1 is a mirror. Textures multiply the base colour as werkstatt's
G-buffer does (texture at uv * uv_scale, bilinear, repeating; Blender's v is 1 - glTF's, so the
scale is taken about v = 1).
"""

import argparse
import json
import math
import os
import sys
import time


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir")
    ap.add_argument("--samples", type=int, default=256)
    ap.add_argument("--direct-only", action="store_true", help="no indirect bounces (max_bounces 0)")
    ap.add_argument("--out", default=None, help="output file name in DIR (default cycles.exr, cycles_direct.exr)")
    ap.add_argument("--half", action="store_true", help="half-float EXR (for committed references)")
    ap.add_argument("--no-ids", action="store_true", help="skip cycles_ids.exr (the item per pixel, as Cycles sees it)")
    ap.add_argument(
        "--only",
        default=None,
        help="render only this item (by name), the others transparent to every ray: with the floor, "
        "a check of the probe against the analytic open-floor value (scene.json open_floor_level)",
    )
    ap.add_argument("--threads", type=int, default=0, help="render threads (0: all cores)")
    ap.add_argument(
        "--albedo",
        action="store_true",
        help="write cycles_albedo.exr instead: every material emits its colour (texture included), the world "
        "is black, one sample at each pixel's centre: Cycles' albedo, to set beside the export's albedo.exr",
    )
    args = ap.parse_args()
    # This file is named cycles.py: keep its folder off the module path, or Blender's own
    # `cycles` add-on would import this script instead.
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != here]
    try:
        import bpy  # noqa: F401
    except ImportError:
        print(
            "cycles.py: skipped: this Python has no Blender module `bpy` "
            "(install it in a Python 3.11 venv: pip install bpy==5.0.0, then run the script with that venv's python)",
            file=sys.stderr,
        )
        return 0
    return render(args)


def to_blender(p):
    """A werkstatt (Y-up) point or direction in Blender's Z-up world."""
    x, y, z = p
    return (x, -z, y)


def phong_to_roughness(g):
    if g >= 1.0:
        return 0.0
    s = 1.0 / (1.0 - g)
    # A Phong lobe cos^s about the reflection is a Blinn-Phong lobe cos^(4s) about the normal
    # in half-vector terms (the reflection turns twice as far as the half vector), and
    # Blinn-Phong n matches Beckmann/GGX alpha^2 = 2 / (n + 2) (Walter et al. 2007).
    alpha = math.sqrt(2.0 / (4.0 * s + 2.0))
    return math.sqrt(alpha)


def linear_float_image(bpy, path):
    """The sRGB PNG at `path` as a linear float image. Cycles keeps an 8-bit sRGB image encoded and
    converts after interpolating, so its bilinear filter would mix sRGB values; werkstatt's
    G-buffer (an Rgba8UnormSrgb texture) mixes linear ones. At the checker's edges the two
    differ by up to 20%; decoded to linear floats here, Cycles filters as werkstatt does."""
    src = bpy.data.images.load(path)
    w, h = src.size
    pixels = list(src.pixels)  # sRGB-encoded, 0..1, RGBA
    for i in range(len(pixels)):
        if i % 4 != 3:
            c = pixels[i]
            pixels[i] = c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4
    img = bpy.data.images.new(os.path.basename(path) + ".linear", w, h, alpha=True, float_buffer=True)
    img.colorspace_settings.name = "Linear Rec.709"
    img.pixels = pixels
    bpy.data.images.remove(src)
    return img


def make_material(bpy, mat, item, folder, hidden=False, albedo=False):
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    if hidden:
        clear = nt.nodes.new("ShaderNodeBsdfTransparent")
        clear.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        nt.links.new(clear.outputs["BSDF"], out.inputs["Surface"])
        return
    g = float(item["glossiness"])
    if albedo:
        bsdf = nt.nodes.new("ShaderNodeEmission")
        bsdf.inputs["Strength"].default_value = 1.0
    elif g > 0.0:
        bsdf = nt.nodes.new("ShaderNodeBsdfGlossy")
        bsdf.distribution = "MULTI_GGX"
        bsdf.inputs["Roughness"].default_value = phong_to_roughness(g)
    else:
        bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
        bsdf.inputs["Roughness"].default_value = 0.0
    base = list(item["base_color"]) + [1.0]
    if item.get("texture"):
        uv = nt.nodes.new("ShaderNodeUVMap")
        mapping = nt.nodes.new("ShaderNodeMapping")
        s = float(item["uv_scale"])
        mapping.inputs["Scale"].default_value = (s, s, 1.0)
        mapping.inputs["Location"].default_value = (0.0, 1.0 - s, 0.0)
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = linear_float_image(bpy, os.path.join(folder, item["texture"]))
        tex.interpolation = "Linear"
        tex.extension = "REPEAT"
        mul = nt.nodes.new("ShaderNodeVectorMath")
        mul.operation = "MULTIPLY"
        mul.inputs[1].default_value = base[:3]
        nt.links.new(uv.outputs["UV"], mapping.inputs["Vector"])
        nt.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
        nt.links.new(tex.outputs["Color"], mul.inputs[0])
        nt.links.new(mul.outputs["Vector"], bsdf.inputs["Color"])
    else:
        bsdf.inputs["Color"].default_value = base
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])


def render_ids(bpy, scene, meshes, world, folder, scene_info):
    """DIR/cycles_ids.exr: every item emits (index + 1, 0, 0), the world is black, one sample at
    each pixel's centre: which item Cycles sees at each pixel (0: none), for `werkstatt
    fidelity compare` to check the ids against."""
    for obj in meshes:
        for slot in obj.material_slots:
            index = int(slot.material.name.split(".")[0][5:])
            nt = slot.material.node_tree
            nt.nodes.clear()
            out = nt.nodes.new("ShaderNodeOutputMaterial")
            em = nt.nodes.new("ShaderNodeEmission")
            em.inputs["Color"].default_value = (index + 1.0, 0.0, 0.0, 1.0)
            em.inputs["Strength"].default_value = 1.0
            nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    for node in world.node_tree.nodes:
        if node.bl_idname == "ShaderNodeBackground":
            node.inputs["Strength"].default_value = 0.0
    scene.cycles.samples = 1
    scene.cycles.max_bounces = 0
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = os.path.join(folder, "cycles_ids.exr")
    bpy.ops.render.render(write_still=True)


def render(args):
    import bpy
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Matrix, Vector

    folder = os.path.abspath(args.dir)
    with open(os.path.join(folder, "scene.json")) as f:
        scene_info = json.load(f)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    t0 = time.time()
    bpy.ops.import_scene.gltf(filepath=os.path.join(folder, "scene.glb"))

    # Materials: the importer names them after the glTF's (part_<item index>).
    items = {i["index"]: i for i in scene_info["items"]}
    meshes = [o for o in scene.objects if o.type == "MESH"]
    for obj in meshes:
        for slot in obj.material_slots:
            name = slot.material.name.split(".")[0]
            if not name.startswith("part_"):
                raise SystemExit(f"cycles.py: unexpected material {slot.material.name}")
            item = items[int(name[5:])]
            hidden = args.only is not None and item["name"] != args.only
            make_material(bpy, slot.material, item, folder, hidden=hidden, albedo=args.albedo)
        # Smooth shading with the file's normals, as the G-buffer interpolates them.
        for poly in obj.data.polygons:
            poly.use_smooth = True

    # Check the axis conversion: the imported geometry's bounds against scene.json's.
    lo = [min(i["bounds_min"][k] for i in scene_info["items"]) for k in range(3)]
    hi = [max(i["bounds_max"][k] for i in scene_info["items"]) for k in range(3)]
    blo = [math.inf] * 3
    bhi = [-math.inf] * 3
    for obj in meshes:
        for v in obj.data.vertices:
            w = obj.matrix_world @ v.co
            for k in range(3):
                blo[k] = min(blo[k], w[k])
                bhi[k] = max(bhi[k], w[k])
    want_lo = [min(a, b) for a, b in zip(to_blender(lo), to_blender(hi))]
    want_hi = [max(a, b) for a, b in zip(to_blender(lo), to_blender(hi))]
    bounds_error = max(max(abs(a - b) for a, b in zip(blo, want_lo)), max(abs(a - b) for a, b in zip(bhi, want_hi)))
    if bounds_error > 1e-3:
        raise SystemExit(f"cycles.py: imported bounds {blo} {bhi} are not scene.json's {want_lo} {want_hi}")

    # Camera.
    cam = scene_info["camera"]
    w, h = scene_info["width"], scene_info["height"]
    cdata = bpy.data.cameras.new("camera")
    cdata.sensor_fit = "VERTICAL"
    cdata.angle_y = math.radians(cam["fov_y_degrees"])
    cdata.clip_start = cam["near"]
    cdata.clip_end = cam["far"]
    cobj = bpy.data.objects.new("camera", cdata)
    scene.collection.objects.link(cobj)
    eye = Vector(to_blender(cam["eye"]))
    target = Vector(to_blender(cam["target"]))
    up = Vector(to_blender(cam["up"]))
    fwd = (target - eye).normalized()
    right = fwd.cross(up).normalized()
    cup = right.cross(fwd)
    rot = Matrix((right, cup, -fwd)).transposed()  # columns: camera x, y, z (looks down -z)
    cobj.matrix_world = Matrix.Translation(eye) @ rot.to_4x4()
    scene.camera = cobj
    scene.render.resolution_x = w
    scene.render.resolution_y = h
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = 1.0
    scene.render.pixel_aspect_y = 1.0
    bpy.context.view_layer.update()

    # The camera check: werkstatt's projections of the bounding-box corners against Blender's.
    worst = 0.0
    for cp in scene_info["check_points"]:
        v = world_to_camera_view(scene, cobj, Vector(to_blender(cp["world"])))
        px = (v.x * w, (1.0 - v.y) * h)
        worst = max(worst, math.hypot(px[0] - cp["pixel"][0], px[1] - cp["pixel"][1]))

    # World: the probe.
    env = scene_info.get("environment")
    world = bpy.data.worlds.new("probe")
    scene.world = world
    if world.node_tree is None:
        world.use_nodes = True
    nt = world.node_tree
    nt.nodes.clear()
    wout = nt.nodes.new("ShaderNodeOutputWorld")
    bg = nt.nodes.new("ShaderNodeBackground")
    if env:
        coord = nt.nodes.new("ShaderNodeTexCoord")
        mapping = nt.nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(-90.0 - env["rotation_deg"]))
        tex = nt.nodes.new("ShaderNodeTexEnvironment")
        tex.image = bpy.data.images.load(env["path"])
        tex.interpolation = "Linear"
        tex.projection = "EQUIRECTANGULAR"
        nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
        nt.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
        nt.links.new(tex.outputs["Color"], bg.inputs["Color"])
        bg.inputs["Strength"].default_value = 0.0 if args.albedo else env["intensity"]
    else:
        bg.inputs["Strength"].default_value = 0.0
    nt.links.new(bg.outputs["Background"], wout.inputs["Surface"])

    # Cycles.
    c = scene.cycles
    c.device = "CPU"
    c.samples = args.samples
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 0.01
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.seed = 0
    if args.albedo:
        c.samples = 1
        c.max_bounces = 0
    elif args.direct_only:
        c.max_bounces = 0
    else:
        c.max_bounces = 16
        c.diffuse_bounces = 8
        c.glossy_bounces = 8
    scene.render.threads_mode = "FIXED" if args.threads else "AUTO"
    if args.threads:
        scene.render.threads = args.threads
    scene.render.film_transparent = False
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_mode = "RGBA"
    settings.color_depth = "16" if args.half else "32"
    settings.exr_codec = "ZIP"
    if args.only is not None and args.only not in {i["name"] for i in scene_info["items"]}:
        raise SystemExit(f"cycles.py: --only {args.only}: no such item")
    default_name = "cycles_direct.exr" if args.direct_only else "cycles.exr"
    if args.only is not None:
        default_name = f"cycles_only_{args.only}.exr"
    if args.albedo:
        default_name = "cycles_albedo.exr"
    name = args.out or default_name
    out_path = os.path.join(folder, name)
    scene.render.filepath = out_path
    t1 = time.time()
    bpy.ops.render.render(write_still=True)
    t2 = time.time()
    if not (args.no_ids or args.albedo):
        render_ids(bpy, scene, meshes, world, folder, scene_info)
    report = {
        "file": name,
        "samples": args.samples,
        "direct_only": args.direct_only,
        "blender": bpy.app.version_string,
        "setup_s": round(t1 - t0, 2),
        "render_s": round(t2 - t1, 2),
        "import_bounds_error": bounds_error,
        "camera_check_max_px": worst,
        "camera_check_points": len(scene_info["check_points"]),
        "ids_file": None if args.no_ids else "cycles_ids.exr",
    }
    with open(os.path.join(folder, os.path.splitext(name)[0] + ".json"), "w") as f:
        json.dump(report, f, indent=2)
    print(
        f"cycles.py: wrote {out_path} ({args.samples} samples, {t2 - t1:.1f} s); "
        f"camera check: {len(scene_info['check_points'])} projected points agree within {worst:.2e} px"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
