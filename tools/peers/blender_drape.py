# Peer benchmark for `werkstatt bench drape`: Blender's cloth simulator on the same sewn garment
# and the same walking body, with equal substeps, self-collision on and the body as a collision
# object; prints its ms per 1/60 s frame and the crossings at the last frame, counted by one rule
# for both simulators (this script's counter, also run on werkstatt's last frame).
#
# Install (Blender 5.0 as a Python module, Python 3.11, about 370 MB):
#   python3 -m venv bpyenv && bpyenv/bin/pip install bpy==5.0.1
# Run:
#   werkstatt bench drape --edges 1 --obj-dir /tmp/drape        (writes /tmp/drape/edge_1cm)
#   bpyenv/bin/python tools/peers/blender_drape.py /tmp/drape/edge_1cm SETTLE WALK [SUBSTEPS [START]]
# START: "rest" (default) sews from the placed panels like werkstatt; "settled" starts from
# werkstatt's settled garment (its shape becomes the rest shape) to compare the walk alone.
# SETTLE: frames the garment hangs on the body at rest (werkstatt's "settled" frames);
# WALK: timed walking frames (werkstatt's --frames). The body file holds 30 blend frames from
# the rest pose to the walk's first frame, then the walk, as werkstatt ran them.
import array, os, statistics, sys, time

import bpy
from mathutils import Vector
from mathutils.bvhtree import BVHTree

folder, settle, walk = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
substeps = int(sys.argv[4]) if len(sys.argv) > 4 else 20
# "rest": sew from the placed panels, as werkstatt does; "settled": start from werkstatt's
# settled garment (its rest shape then), for the walk alone.
start = sys.argv[5] if len(sys.argv) > 5 else "rest"
BLEND = 30


def read_obj(path):
    verts, tris, lines = [], [], []
    for line in open(path):
        t = line.split()
        if not t:
            continue
        if t[0] == "v":
            verts.append(tuple(map(float, t[1:4])))
        elif t[0] == "f":
            tris.append(tuple(int(i.split("/")[0]) - 1 for i in t[1:4]))
        elif t[0] == "l":
            lines.append((int(t[1]) - 1, int(t[2]) - 1))
    return verts, tris, lines


def make_object(name, verts, tris, lines):
    # Built from data, not the importer: the importer's axis conversion and its handling of
    # line elements would change the vertex order or positions.
    mesh = bpy.data.meshes.new(name)
    edges = [tuple(l) for l in lines]
    mesh.from_pydata(verts, edges, tris)
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.fps = 60
# werkstatt is y-up: the same coordinates, gravity along -y.
scene.gravity = (0.0, -9.81, 0.0)
scene.use_gravity = os.environ.get("PEER_NOGRAV") is None

g_verts, g_tris, seams = read_obj(os.path.join(folder, "garment_rest.obj"))
if start == "settled":
    g_verts = read_obj(os.path.join(folder, "garment_settled.obj"))[0]
b_verts, b_tris, _ = read_obj(os.path.join(folder, "body_rest.obj"))
raw = array.array("f")
with open(os.path.join(folder, "body_frames.f32"), "rb") as f:
    raw.frombytes(f.read())
nb = len(b_verts)
n_frames = len(raw) // (3 * nb)
assert n_frames >= BLEND + walk, (n_frames, BLEND, walk)

garment = make_object("garment", g_verts, g_tris, seams)
body = make_object("body", b_verts, b_tris, [])

col = body.modifiers.new("collision", "COLLISION")
body.collision.thickness_outer = 0.0025
body.collision.cloth_friction = 5.0

cloth = garment.modifiers.new("cloth", "CLOTH")
s = cloth.settings
s.quality = substeps
# Same areal density as werkstatt (0.2 kg/m^2), spread over the vertices.
area = sum((Vector(g_verts[b]) - Vector(g_verts[a])).cross(Vector(g_verts[c]) - Vector(g_verts[a])).length / 2 for a, b, c in g_tris)
s.mass = 0.2 * area / len(g_verts)
s.use_sewing_springs = True
s.air_damping = 1.0
# As werkstatt sews: gravity off for the first 30 frames while the seams close.
s.effector_weights.gravity = 0.0
s.effector_weights.keyframe_insert("gravity", frame=1)
s.effector_weights.keyframe_insert("gravity", frame=30)
s.effector_weights.gravity = 1.0
s.effector_weights.keyframe_insert("gravity", frame=31)
c = cloth.collision_settings
c.use_collision = True
c.distance_min = 0.0025
c.use_self_collision = True
c.self_distance_min = 0.002
cache = cloth.point_cache
total = settle + BLEND + walk
cache.frame_start = 1
cache.frame_end = total + 1
scene.frame_start, scene.frame_end = 1, total + 1

flat_rest = [x for v in b_verts for x in v]


def set_body(frame):
    # Frames 1..settle+1: rest; then the recorded blend and walk, one pose per frame.
    k = frame - settle - 2
    co = flat_rest if k < 0 else raw[3 * nb * k: 3 * nb * (k + 1)]
    body.data.vertices.foreach_set("co", co)
    body.data.update()


bpy.app.handlers.frame_change_pre.append(lambda sc, *a: set_body(sc.frame_current))

def cloth_positions():
    deps = bpy.context.evaluated_depsgraph_get()
    ev = garment.evaluated_get(deps)
    return [tuple(v.co) for v in ev.data.vertices]


times = []
t_all = time.perf_counter()
for f in range(1, total + 2):
    t0 = time.perf_counter()
    scene.frame_set(f)
    times.append((time.perf_counter() - t0) * 1e3)
    if os.environ.get("PEER_DEBUG") and f % 10 == 0:
        v = cloth_positions()
        ys = [p[1] for p in v]
        print(f"frame {f}: stitch gap {max((Vector(v[a]) - Vector(v[b])).length for a, b in seams) * 1e3:.1f} mm, y {min(ys):.3f}..{max(ys):.3f}")
elapsed = time.perf_counter() - t_all
settle_ms = sum(times[: settle + 1])
walk_ms = times[settle + 1 + BLEND:]


def crossings(cv, tris, seams, bv, btris):
    # One rule for both simulators: an edge crossing the body's triangles; an edge crossing a
    # cloth triangle that shares no vertex with it, sewn vertices counting as one.
    rep = list(range(len(cv)))
    def root(i):
        while rep[i] != i:
            i = rep[i]
        return i
    for a, b in seams:
        ra, rb = root(a), root(b)
        rep[max(ra, rb)] = min(ra, rb)
    reps = [root(i) for i in range(len(cv))]
    edges = set()
    for t in tris:
        for k in range(3):
            a, b = t[k], t[(k + 1) % 3]
            edges.add((min(a, b), max(a, b)))
    body_tree = BVHTree.FromPolygons(bv, btris)
    cloth_tree = BVHTree.FromPolygons(cv, tris)
    tri_reps = [{reps[i] for i in t} for t in tris]
    n_body = n_self = 0
    for a, b in edges:
        pa, pb = Vector(cv[a]), Vector(cv[b])
        d = pb - pa
        length = d.length
        if length == 0:
            continue
        d /= length
        if body_tree.ray_cast(pa, d, length)[0] is not None:
            n_body += 1
        # Walk along the edge through the hits, skipping the triangles around its own ends.
        start, left = pa, length
        while left > 1e-7:
            hit, _, index, dist = cloth_tree.ray_cast(start, d, left)
            if hit is None:
                break
            if reps[a] not in tri_reps[index] and reps[b] not in tri_reps[index]:
                n_self += 1
                break
            step = dist + 1e-6
            start, left = start + d * step, left - step
    return n_body, n_self


last_body = raw[3 * nb * (BLEND + walk - 1): 3 * nb * (BLEND + walk)]
last_bv = [tuple(last_body[3 * i: 3 * i + 3]) for i in range(nb)]
peer_v = cloth_positions()
peer = crossings(peer_v, g_tris, seams, last_bv, b_tris)
with open(os.path.join(folder, "blender_walked.obj"), "w") as f:
    f.writelines(f"v {x} {y} {z}\n" for x, y, z in peer_v)
    f.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in g_tris)
ours_v, _, _ = read_obj(os.path.join(folder, "garment_walked.obj"))
ours = crossings(ours_v, g_tris, seams, last_bv, b_tris)


def seam_gap_mm(v):
    return max((Vector(v[a]) - Vector(v[b])).length for a, b in seams) * 1e3


def height(v):
    ys = [p[1] for p in v]
    return f"y {min(ys):.3f} to {max(ys):.3f} m"
print(f"blender {bpy.app.version_string}: {len(g_verts)} particles, {substeps} substeps, self-collision on")
print(f"settling {settle + 1} frames: {settle_ms:.0f} ms")
print(f"walking: {statistics.mean(walk_ms):.2f} ms/frame (median {statistics.median(walk_ms):.2f}) over {len(walk_ms)} frames")
print(f"last frame, body crossings / self crossings: blender {peer[0]} / {peer[1]}, werkstatt {ours[0]} / {ours[1]}")
print(f"last frame, largest stitch gap: blender {seam_gap_mm(peer_v):.1f} mm, werkstatt {seam_gap_mm(ours_v):.1f} mm")
print(f"last frame, extent: blender {height(peer_v)}, werkstatt {height(ours_v)}")
