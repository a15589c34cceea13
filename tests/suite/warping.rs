//! Deferred warping against analytic ground truth: matrix textures of a plane, a cylinder and
//! a sphere; warped vertices through the GPU export path against the analytic surface frame
//! and against the CPU reference; no shear on sheared UVs; outliers discarded.
//! Tolerances are stated relative to the world size of one texel.

use std::f32::consts::{PI, TAU};
use std::sync::Arc;

use glam::{Vec2, Vec3};
use werkstatt::mesh::Mesh;
use werkstatt::nodes::mesh::geometry;
use werkstatt::nodes::warp::attach::point_instance;
use werkstatt::nodes::warp::matrix_texture::MatrixTextureNode;
use werkstatt::warp::gpu::GpuWarper;
use werkstatt::warp::gpu::read_matrix;
use werkstatt::warp::{
    AttachedDraw, InstanceData, MatrixTexels, Placement, WarpMode, WarpSettings, warp_layout_cpu, warp_vertex_cpu,
};

use crate::common;

const F32: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

fn matrix(
    mesh: &Mesh,
    res: u32,
    format: wgpu::TextureFormat,
    filter: u32,
) -> (Arc<werkstatt::warp::MatrixTexture>, MatrixTexels) {
    let gpu = common::gpu();
    let m = MatrixTextureNode::default().render(gpu, mesh, res, format, filter, None).unwrap();
    let texels = read_matrix(gpu, &m).unwrap();
    (Arc::new(m), texels)
}

fn texel_uv(res: u32, x: u32, y: u32) -> Vec2 {
    Vec2::new((x as f32 + 0.5) / res as f32, (y as f32 + 0.5) / res as f32)
}

/// Checks every covered texel against (position, t_u, n, t_v) of `truth(u, v)`.
fn check_frames(
    texels: &MatrixTexels,
    texel_world: f32,
    pos_tol_texels: f32,
    dot_min: f32,
    truth: impl Fn(Vec2) -> Option<[Vec3; 4]>,
) -> usize {
    let res = texels.resolution;
    let mut checked = 0;
    for y in 0..res {
        for x in 0..res {
            let Some([p, tu, n, tv]) = truth(texel_uv(res, x, y)) else { continue };
            if texels.is_empty_texel(x, y) {
                continue;
            }
            let f = texels.at(x, y);
            let err = (f.p - p).length() / texel_world;
            assert!(err < pos_tol_texels, "texel ({x},{y}): position {:?} vs {p:?} ({err} texels)", f.p);
            assert!(
                f.tu.dot(tu) > dot_min && f.n.dot(n) > dot_min && f.tv.dot(tv) > dot_min,
                "texel ({x},{y}): frame {f:?} vs {tu:?} {n:?} {tv:?}"
            );
            // Orthonormal, right-handed for these parametrizations.
            assert!(f.tu.dot(f.n).abs() < 1e-4 && f.tu.dot(f.tv).abs() < 1e-4 && f.n.dot(f.tv).abs() < 1e-4);
            checked += 1;
        }
    }
    checked
}

#[test]
fn plane_matrix_texture_is_exact() {
    let res = 64;
    let (_, texels) = matrix(&geometry::plane(2.0, 8, 8).unwrap(), res, F32, 0);
    let n = check_frames(&texels, 2.0 / res as f32, 1e-3, 0.99999, |uv| {
        Some([Vec3::new((uv.x - 0.5) * 2.0, 0.0, (uv.y - 0.5) * 2.0), Vec3::X, Vec3::Y, Vec3::Z])
    });
    assert_eq!(n, (res * res) as usize, "every texel of a plane covering [0,1]^2 is covered");
}

#[test]
fn cylinder_matrix_texture_matches_the_parametrization() {
    let (r, h, res) = (0.5f32, 1.0f32, 128);
    let (_, texels) = matrix(&geometry::cylinder(r, h, 256, 4).unwrap(), res, F32, 0);
    let texel_world = TAU * r / res as f32;
    // Chord error of 256 segments: r (1 - cos(pi/256)) = 0.0008 texels here.
    let n = check_frames(&texels, texel_world, 0.01, 0.9998, |uv| {
        let a = uv.x * TAU;
        let normal = Vec3::new(a.sin(), 0.0, a.cos());
        Some([normal * r + Vec3::Y * h * (0.5 - uv.y), Vec3::new(a.cos(), 0.0, -a.sin()), normal, -Vec3::Y])
    });
    assert!(n > (res * res) as usize * 99 / 100);
}

#[test]
fn sphere_patch_matrix_texture_matches_the_parametrization() {
    let (r, res) = (0.5f32, 128);
    let (_, texels) = matrix(&geometry::sphere(r, 256, 128).unwrap(), res, F32, 0);
    let texel_world = TAU * r / res as f32;
    let n = check_frames(&texels, texel_world, 0.02, 0.9995, |uv| {
        // The patch away from the poles, where the parametrization is regular.
        if !(0.2..0.8).contains(&uv.y) {
            return None;
        }
        let (phi, theta) = (uv.x * TAU, uv.y * PI);
        let normal = Vec3::new(theta.sin() * phi.sin(), theta.cos(), theta.sin() * phi.cos());
        let tu = Vec3::new(phi.cos(), 0.0, -phi.sin());
        let tv = Vec3::new(theta.cos() * phi.sin(), -theta.sin(), theta.cos() * phi.cos());
        Some([normal * r, tu, normal, tv])
    });
    assert!(n > 5000, "{n}");
}

#[test]
fn half_float_path_matches_the_float_path() {
    let mesh = geometry::cylinder(0.5, 1.0, 128, 4).unwrap();
    let (_, a) = matrix(&mesh, 64, F32, 0);
    let (_, b) = matrix(&mesh, 64, wgpu::TextureFormat::Rgba16Float, 0);
    assert_eq!(a.frames.len(), b.frames.len());
    for (fa, fb) in a.frames.iter().zip(&b.frames) {
        assert!((fa.p - fb.p).length() < 1e-3 && (fa.n - fb.n).length() < 2e-3, "{fa:?} vs {fb:?}");
    }
}

#[test]
fn filtering_keeps_positions_and_orthonormal_frames() {
    let mesh = geometry::sphere(0.5, 64, 32).unwrap();
    let (_, raw) = matrix(&mesh, 64, F32, 0);
    let (_, smooth) = matrix(&mesh, 64, F32, 3);
    let mut changed = 0.0f32;
    assert_eq!(raw.frames.len(), smooth.frames.len());
    for (a, b) in raw.frames.iter().zip(&smooth.frames) {
        if a.n.length_squared() < 0.25 {
            assert_eq!(b.n, Vec3::ZERO, "empty texels stay empty");
            continue;
        }
        assert_eq!(a.p, b.p, "positions are not filtered");
        assert!((b.n.length() - 1.0).abs() < 1e-4 && b.n.dot(b.tu).abs() < 1e-4 && b.n.dot(b.tv).abs() < 1e-4);
        changed = changed.max(1.0 - a.n.dot(b.n));
    }
    assert!(changed > 1e-4, "the filter changed nothing");
}

fn warp_gpu(
    matrix: Arc<werkstatt::warp::MatrixTexture>,
    mesh: &Mesh,
    settings: WarpSettings,
    instances: Vec<InstanceData>,
) -> Vec<werkstatt::warp::WarpedVertex> {
    let gpu = common::gpu();
    let draw = AttachedDraw::new(matrix, settings, instances);
    GpuWarper::default().warp(gpu, mesh, &draw).unwrap()
}

const POINT: WarpSettings = WarpSettings { mode: WarpMode::Point, gravity: 0.0, min_weight: 0.5 };

#[test]
fn point_attachment_on_a_cylinder_matches_the_analytic_frame() {
    let (r, h) = (0.5f32, 1.0f32);
    let (m, _) = matrix(&geometry::cylinder(r, h, 256, 8).unwrap(), 256, F32, 0);
    let detail = geometry::cube(1.0).unwrap();
    let places: Vec<Placement> = (0..12)
        .map(|i| Placement { piece: 0, u: 0.04 + 0.08 * i as f32, v: 0.3 + 0.03 * i as f32, angle: 0.0, scale: 1.0 })
        .collect();
    let (scale, lift) = (0.05, 0.01);
    let instances = places.iter().map(|p| point_instance(p, scale, 1.0, lift, 0.0)).collect();
    let warped = warp_gpu(m, &detail, POINT, instances);
    let texel_world = TAU * r / 256.0;
    assert_eq!(warped.len(), places.len() * detail.positions.len(), "one warped vertex per instance and vertex");
    for (p, verts) in places.iter().zip(warped.chunks(detail.positions.len())) {
        let a = p.u * TAU;
        let n = Vec3::new(a.sin(), 0.0, a.cos());
        let (tu, tv) = (Vec3::new(a.cos(), 0.0, -a.sin()), -Vec3::Y);
        let origin = n * r + Vec3::Y * h * (0.5 - p.v);
        for (w, q) in verts.iter().zip(&detail.positions) {
            assert!(w.valid);
            let q = *q * scale + Vec3::new(0.0, lift, 0.0);
            let expected = origin + tu * q.x + n * q.y + tv * q.z;
            let err = (w.position - expected).length() / texel_world;
            assert!(err < 0.05, "placement {p:?}: {:?} vs {expected:?} ({err} texels)", w.position);
        }
    }
}

#[test]
fn gpu_warp_equals_the_cpu_reference_for_every_mode() {
    let surface = geometry::sphere(0.5, 64, 32).unwrap();
    let (m, texels) = matrix(&surface, 128, F32, 0);
    let detail = geometry::torus(0.4, 0.15, 12, 6).unwrap();
    let curve = [Vec2::new(0.1, 0.3), Vec2::new(0.3, 0.1), Vec2::new(0.6, 0.7), Vec2::new(0.9, 0.5)];
    let cases = [
        (
            WarpMode::Point,
            // The second lies off the texture: an outlier on both sides.
            [0.3, 1.5]
                .map(|u| {
                    point_instance(&Placement { piece: 0, u, v: 0.4, angle: 30.0, scale: 1.0 }, 0.1, 2.0, 0.0, 0.0)
                })
                .to_vec(),
        ),
        // Unattached (mode 4) also takes the CPU twin's one-frame-per-instance path.
        (
            WarpMode::Unattached,
            vec![point_instance(&Placement { piece: 0, u: 0.6, v: 0.2, angle: 10.0, scale: 1.0 }, 0.1, 2.0, 0.0, 0.0)],
        ),
        (
            WarpMode::Area,
            vec![InstanceData::identity().with_tex(glam::Affine2::from_scale_angle_translation(
                Vec2::splat(0.1),
                0.3,
                Vec2::new(0.5, 0.5),
            ))],
        ),
        (
            WarpMode::Curve,
            vec![
                InstanceData::identity()
                    .with_tan(glam::Mat4::from_scale(Vec3::splat(0.05)))
                    .with_curve(&curve, 0.2, 0.4, -0.55, 0.55),
            ],
        ),
        (
            WarpMode::CurveAligned,
            vec![
                InstanceData::identity()
                    .with_tan(glam::Mat4::from_scale(Vec3::splat(0.05)))
                    .with_curve(&curve, 0.5, 0.7, -0.55, 0.55),
            ],
        ),
    ];
    for (mode, instances) in cases {
        for gravity in [0.0, 2.0] {
            let s = WarpSettings { mode, gravity, min_weight: 0.5 };
            let gpu = warp_gpu(m.clone(), &detail, s, instances.clone());
            let cpu = warp_layout_cpu(&texels, &s, &detail, &instances).vertices();
            // The threaded twin (one frame per point instance) is exactly the per-vertex reference.
            let nv = detail.positions.len();
            for (i, c) in cpu.iter().enumerate() {
                let (k, v) = (i / nv, i % nv);
                let r = warp_vertex_cpu(&texels, &s, &instances[k], detail.positions[v], detail.normals[v]);
                assert_eq!(c.valid, r.valid, "{mode:?} gravity {gravity}: instance {k} vertex {v}");
                if r.valid {
                    assert_eq!((c.position, c.normal), (r.position, r.normal), "{mode:?} gravity {gravity}");
                }
            }
            // Equal lengths, and something valid: an empty or all-outlier GPU result must fail.
            assert_eq!(gpu.len(), instances.len() * detail.positions.len(), "{mode:?}");
            assert_eq!(gpu.len(), cpu.len(), "{mode:?}");
            assert!(gpu.iter().any(|g| g.valid), "{mode:?}: no valid vertex");
            assert!(mode != WarpMode::Point || gpu.iter().any(|g| !g.valid), "the point outlier is kept");
            for (g, c) in gpu.iter().zip(&cpu) {
                assert_eq!(g.valid, c.valid, "{mode:?}");
                if g.valid {
                    assert!(
                        (g.position - c.position).length() < 1e-4,
                        "{mode:?} gravity {gravity}: {:?} vs {:?}",
                        g.position,
                        c.position
                    );
                    assert!((g.normal - c.normal).length() < 1e-3, "{mode:?}: normal {:?} vs {:?}", g.normal, c.normal);
                }
            }
        }
    }
}

#[test]
fn point_attachments_are_not_sheared_by_a_sheared_parametrization() {
    // A plane whose UVs are sheared: u = x + 0.6 z. t_u and t_v are 31 degrees from orthogonal.
    let mut plane = geometry::plane(1.0, 16, 16).unwrap();
    let uvs: Vec<Vec2> = plane.positions.iter().map(|p| Vec2::new((p.x + 0.6 * p.z) / 1.6 + 0.5, p.z + 0.5)).collect();
    plane =
        Mesh::build(plane.positions.clone(), Some(uvs), Some(plane.normals.clone()), plane.indices.clone()).unwrap();
    let (m, _) = matrix(&plane, 128, F32, 0);
    let detail = geometry::cube(1.0).unwrap();
    let inst = point_instance(&Placement { piece: 0, u: 0.5, v: 0.5, angle: 20.0, scale: 1.0 }, 0.1, 1.0, 0.0, 0.0);
    let w = warp_gpu(m, &detail, POINT, vec![inst]);
    // Rigid: every pairwise distance equals the scaled original.
    for i in 0..detail.positions.len() {
        for j in 0..i {
            let d0 = (detail.positions[i] - detail.positions[j]).length() * 0.1;
            let d1 = (w[i].position - w[j].position).length();
            assert!((d0 - d1).abs() < 1e-5, "distance {i}-{j}: {d0} became {d1}");
        }
    }
    // And upright: the cube's y axis is the plane normal.
    let top = w.iter().map(|v| v.position.y).fold(f32::MIN, f32::max);
    assert!((top - 0.05).abs() < 1e-5, "{top}");
}

#[test]
fn lookups_outside_the_pieces_are_outliers() {
    // A surface covering only the left half of UV space.
    let mut plane = geometry::plane(1.0, 8, 8).unwrap();
    let uvs: Vec<Vec2> = plane.uvs.iter().map(|uv| Vec2::new(uv.x * 0.5, uv.y)).collect();
    plane =
        Mesh::build(plane.positions.clone(), Some(uvs), Some(plane.normals.clone()), plane.indices.clone()).unwrap();
    let (m, _) = matrix(&plane, 64, F32, 0);
    let detail = geometry::cube(1.0).unwrap();
    let inside = point_instance(&Placement { piece: 0, u: 0.25, v: 0.5, angle: 0.0, scale: 1.0 }, 0.05, 1.0, 0.0, 0.0);
    let outside = point_instance(&Placement { piece: 0, u: 0.75, v: 0.5, angle: 0.0, scale: 1.0 }, 0.05, 1.0, 0.0, 0.0);
    let w = warp_gpu(m, &detail, POINT, vec![inside, outside]);
    let n = detail.positions.len();
    assert!(w[..n].iter().all(|v| v.valid));
    assert!(w[n..].iter().all(|v| !v.valid), "a lookup on empty texels must be flagged");
}

/// Two pieces of one flat garment sewn along x = 0; piece B is turned 90 degrees in the atlas.
fn sewn_plane(sewn: bool) -> Mesh {
    let n = 8;
    let (mut p, mut uv, mut idx, mut piece) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (pi, x0) in [(0u32, -1.0f32), (1, 0.0)] {
        let base = p.len() as u32;
        for j in 0..=n {
            for i in 0..=n {
                let (x, z) = (x0 + i as f32 / n as f32, j as f32 / n as f32 - 0.5);
                p.push(Vec3::new(x, 0.0, z));
                uv.push(if pi == 0 {
                    Vec2::new(0.05 + (x + 1.0) * 0.4, 0.3 + (z + 0.5) * 0.4)
                } else {
                    // t_u = +z, t_v = -x: a quarter turn in the atlas.
                    Vec2::new(0.55 + (z + 0.5) * 0.4, 0.3 + (1.0 - x) * 0.4)
                });
                piece.push(pi);
            }
        }
        for j in 0..n {
            for i in 0..n {
                let a = base + j * (n + 1) + i;
                idx.extend_from_slice(&[a, a + n + 1, a + 1, a + 1, a + n + 1, a + n + 2]);
            }
        }
    }
    let mut m = Mesh::from_parts(p, Some(vec![Vec3::Y; 2 * (n as usize + 1).pow(2)]), uv, idx, piece).unwrap();
    if sewn {
        // A's column i = n (x = 0) meets B's column i = 0 (x = 0).
        let row = n + 1;
        m.seams = (0..=n).map(|j| [j * row + n, row * row + j * row]).collect();
    }
    m
}

#[test]
fn lookups_past_a_seam_blend_into_the_partner_piece() {
    let res = 128;
    let s = WarpSettings { mode: WarpMode::Point, gravity: 0.0, min_weight: 0.5 };
    let detail = geometry::cube(1.0).unwrap();
    // Along A's centre line, from inside A across its sewn edge (u = 0.45) into the gutter.
    let us: Vec<f32> = (0..14).map(|k| 0.44 + 0.0015 * k as f32).collect();
    let places: Vec<InstanceData> = us
        .iter()
        .map(|&u| point_instance(&Placement { piece: 0, u, v: 0.5, angle: 0.0, scale: 1.0 }, 0.01, 1.0, 0.0, 0.0))
        .collect();
    let (m, texels) = matrix(&sewn_plane(true), res, F32, 0);
    let (_, unsewn) = matrix(&sewn_plane(false), res, F32, 0);
    let gpu = warp_gpu(m, &detail, s, places.clone());
    let nv = detail.positions.len();
    let mut outside_seam = 0;
    for (k, &u) in us.iter().enumerate() {
        let frame =
            texels.lookup(Vec2::new(u, 0.5), 0.5).unwrap_or_else(|| panic!("u = {u}: outlier despite the seam"));
        // The same flat frame on both sides: B's turned tangents were turned back.
        assert!(
            frame.tu.dot(Vec3::X) > 0.9999 && frame.n.dot(Vec3::Y) > 0.9999 && frame.tv.dot(Vec3::Z) > 0.9999,
            "u = {u}: {frame:?}"
        );
        // Positions continue across the seam: x = (u - 0.05) / 0.4 - 1.
        let x = (u - 0.05) / 0.4 - 1.0;
        // The partner point is read bilinearly: exact on this flat garment (its nearest texel
        // was up to 0.7 texel = 0.014 off). One texel is 1 / (0.4 res) world units.
        let texel = 1.0 / (0.4 * res as f32);
        assert!((frame.p.x - x).abs() < 0.02 * texel, "u = {u}: x {} vs {x}", frame.p.x);
        // The GPU agrees with the CPU reference.
        let g = &gpu[k * nv];
        let c = werkstatt::warp::warp_vertex_cpu(&texels, &s, &places[k], detail.positions[0], detail.normals[0]);
        assert!(g.valid && (g.position - c.position).length() < 1e-4, "u = {u}: {:?} vs {:?}", g.position, c.position);
        if unsewn.lookup(Vec2::new(u, 0.5), 0.5).is_none() {
            outside_seam += 1;
        }
    }
    assert!(outside_seam >= 3, "without the seam, lookups past the edge must be outliers ({outside_seam})");
}

/// Deferred warping needs right-handed frames ((t_u x n) . t_v > 0) or attached geometry is
/// mirrored: check the built-in cloth's parametrization, piece by piece.
#[test]
fn cloth_matrix_frames_are_right_handed() {
    use werkstatt::cloth::{FlagParams, Preset, SkirtParams};
    for preset in [
        Preset::Skirt(SkirtParams { triangles: 1500, ..Default::default() }),
        Preset::Flag(FlagParams { triangles: 800, ..Default::default() }),
    ] {
        let f = preset.build().surface();
        let v3 = |a: &[[f32; 3]]| a.iter().map(|p| Vec3::from_array(*p)).collect::<Vec<_>>();
        let mesh = Mesh::from_parts(
            v3(&f.positions),
            Some(v3(&f.normals)),
            f.uvs.iter().map(|t| Vec2::from_array(*t)).collect(),
            f.indices,
            f.piece_ids,
        )
        .unwrap();
        let (_, texels) = matrix(&mesh, 128, F32, 0);
        let (mut right, mut left) = (0, 0);
        for t in texels.frames.iter().filter(|t| t.n.length_squared() > 0.25) {
            if t.tu.cross(t.n).dot(t.tv) > 0.0 { right += 1 } else { left += 1 }
        }
        assert!(right > 1000 && left * 100 < right, "{preset:?}: {right} right-handed texels, {left} left-handed");
    }
}

// ---- Area, curve and fur attachments against closed forms (eqs. 6-12) ----

/// A tile over x, z in [-0.5, 0.5] with height y = kx x + kz z (a tilted ridge; flat for 0, 0)
/// and its exact normal, `cells` x `cells` quads.
fn tilted_tile(kx: f32, kz: f32, cells: u32) -> Mesh {
    let n = Vec3::new(-kx, 1.0, -kz).normalize();
    let (mut p, mut uv, mut idx) = (Vec::new(), Vec::new(), Vec::new());
    for j in 0..=cells {
        for i in 0..=cells {
            let (x, z) = (i as f32 / cells as f32 - 0.5, j as f32 / cells as f32 - 0.5);
            p.push(Vec3::new(x, kx * x + kz * z, z));
            uv.push(Vec2::new(x + 0.5, z + 0.5));
        }
    }
    for j in 0..cells {
        for i in 0..cells {
            let a = j * (cells + 1) + i;
            idx.extend_from_slice(&[a, a + cells + 1, a + 1, a + 1, a + cells + 1, a + cells + 2]);
        }
    }
    let count = p.len();
    Mesh::from_parts(p, Some(vec![n; count]), uv, idx, vec![]).unwrap()
}

const AREA: WarpSettings = WarpSettings { mode: WarpMode::Area, gravity: 0.0, min_weight: 0.5 };

/// Eq. 6-7: a flat tile lifted by `lift` lies at distance r + lift from a cylinder's axis and
/// from a sphere's centre, every vertex.
#[test]
fn area_tiles_on_a_cylinder_and_a_sphere_lie_at_the_lifted_radius() {
    let (r, lift) = (0.5f32, 0.02f32);
    let tile = tilted_tile(0.0, 0.0, 4);
    let inst = |u: f32, v: f32| {
        InstanceData::identity()
            .with_tex(glam::Affine2::from_scale_angle_translation(Vec2::splat(0.1), 0.4, Vec2::new(u, v)))
            .with_tan(glam::Mat4::from_translation(Vec3::new(0.0, lift, 0.0)))
    };
    type Distance = fn(Vec3) -> f32;
    let distance: [(Mesh, Distance); 2] = [
        (geometry::cylinder(r, 1.0, 256, 4).unwrap(), |p| Vec2::new(p.x, p.z).length()),
        (geometry::sphere(r, 256, 128).unwrap(), |p| p.length()),
    ];
    for (surface, dist) in distance {
        let (m, _) = matrix(&surface, 128, F32, 0);
        let w = warp_gpu(m, &tile, AREA, vec![inst(0.3, 0.5), inst(0.7, 0.4)]);
        assert_eq!(w.len(), 2 * tile.positions.len());
        for v in &w {
            assert!(v.valid);
            // Chord and bilinear sagitta at 128 texels: r (1 - cos(pi / 128)) = 1.5e-4.
            let d = dist(v.position);
            assert!((d - (r + lift)).abs() < 4e-4, "{:?} at {d}, not {}", v.position, r + lift);
        }
    }
}

/// The angle between two unit vectors in degrees.
fn degrees(a: Vec3, b: Vec3) -> f32 {
    a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Eqs. 6-7 for normals: a ridge y = k x on a cylinder (2 pi r world units per u, h per v)
/// through M_tex of scale s and height H has world slope H k / (s 2 pi r) along t_u; along
/// t_v (y = k z) H k / (s h). The normal tilts from the cloth normal by the arctangent.
#[test]
fn area_attachment_normals_tilt_by_the_ridge_slope_and_the_tile_scale() {
    let (r, h, s, height) = (0.5f32, 1.0f32, 0.1f32, 1.0f32);
    let (m, _) = matrix(&geometry::cylinder(r, h, 256, 4).unwrap(), 128, F32, 0);
    let (u, v) = (0.3f32, 0.5f32);
    let a = u * TAU;
    let (n, tu, tv) = (Vec3::new(a.sin(), 0.0, a.cos()), Vec3::new(a.cos(), 0.0, -a.sin()), -Vec3::Y);
    let inst = InstanceData::identity()
        .with_tex(glam::Affine2::from_scale_angle_translation(Vec2::splat(s), 0.0, Vec2::new(u, v)))
        .with_tan(glam::Mat4::from_scale(Vec3::new(1.0, height, 1.0)));
    for (kx, kz) in [(0.1f32, 0.0f32), (0.0, 0.05)] {
        let (slope_u, slope_v) = (height * kx / (s * TAU * r), height * kz / (s * h));
        let expected = (n - tu * slope_u - tv * slope_v).normalize();
        let tile = tilted_tile(kx, kz, 2);
        let w = warp_gpu(m.clone(), &tile, AREA, vec![inst]);
        assert!(w.iter().all(|v| v.valid));
        // The centre vertex: the tile's (0, 0) sits at (u, v).
        let c = &w[tile.positions.iter().position(|p| p.x == 0.0 && p.z == 0.0).unwrap()];
        let want = degrees(expected, n);
        let got = degrees(c.normal, n);
        assert!(degrees(c.normal, expected) < 0.3, "ridge ({kx}, {kz}): normal tilts {got} deg, not {want}");
    }
}

const fn curve_settings(aligned: bool) -> WarpSettings {
    WarpSettings { mode: if aligned { WarpMode::CurveAligned } else { WarpMode::Curve }, gravity: 0.0, min_weight: 0.5 }
}

/// Eqs. 8-10 on a plane of side 2 (world = 2 (uv - 0.5), t_u = x, n = y, t_v = z): a cube
/// along a straight and along a (Bezier quarter-) circular curve, aligned and unaligned.
#[test]
fn curve_attachments_follow_straight_and_circular_curves() {
    let world = |uv: Vec2| Vec3::new((uv.x - 0.5) * 2.0, 0.0, (uv.y - 0.5) * 2.0);
    let (m, _) = matrix(&geometry::plane(2.0, 4, 4).unwrap(), 64, F32, 0);
    let cube = geometry::cube(1.0).unwrap();
    let s = 0.05f32;
    // A straight curve at 30 degrees from +u, parametrized linearly.
    let (a, d) = (Vec2::new(0.25, 0.3), Vec2::new(30f32.to_radians().cos(), 30f32.to_radians().sin()));
    let line = [a, a + d * 0.1, a + d * 0.2, a + d * 0.3];
    let inst = InstanceData::identity().with_tan(glam::Mat4::from_scale(Vec3::splat(s)));
    for aligned in [false, true] {
        let w =
            warp_gpu(m.clone(), &cube, curve_settings(aligned), vec![inst.with_curve(&line, 0.25, 0.75, -0.5, 0.5)]);
        let dw = Vec3::new(d.x, 0.0, d.y);
        // The offset direction of x: t_u (eq. 9), or the curve normal n_c = (d_v, -d_u) (eq. 10).
        let across = if aligned { Vec3::new(d.y, 0.0, -d.x) } else { Vec3::X };
        for (v, (p, nrm)) in w.iter().zip(cube.positions.iter().zip(&cube.normals)) {
            assert!(v.valid);
            let t = 0.25 + 0.5 * (p.z + 0.5);
            let expected = world(a + d * 0.3 * t) + across * (s * p.x) + Vec3::Y * (s * p.y);
            assert!((v.position - expected).length() < 1e-4, "aligned {aligned}: {:?} vs {expected:?}", v.position);
            // A face's normal is the cross product of the world images of its two edge
            // directions, on the side its own axis points to.
            let e = [across, Vec3::Y, dw];
            let f = if nrm.x.abs() > 0.5 {
                0
            } else if nrm.y.abs() > 0.5 {
                1
            } else {
                2
            };
            let cross = e[(f + 1) % 3].cross(e[(f + 2) % 3]);
            let outward = cross.normalize() * nrm[f].signum() * e[f].dot(cross).signum();
            assert!(
                v.normal.dot(outward) > 0.9999,
                "aligned {aligned}: normal {:?} vs {outward:?} ({nrm:?})",
                v.normal
            );
        }
    }
    // A quarter circle of UV radius 0.25 about (0.5, 0.5) from +u to +v (world radius 0.5).
    let (c, k) = (Vec2::splat(0.5), 0.552_284_8f32);
    let arc = [
        c + Vec2::new(0.25, 0.0),
        c + Vec2::new(0.25, 0.25 * k),
        c + Vec2::new(0.25 * k, 0.25),
        c + Vec2::new(0.0, 0.25),
    ];
    let instances: Vec<_> =
        (0..4).map(|i| inst.with_curve(&arc, i as f32 / 4.0, (i + 1) as f32 / 4.0, -0.5, 0.5)).collect();
    for aligned in [false, true] {
        let w = warp_gpu(m.clone(), &cube, curve_settings(aligned), instances.clone());
        assert_eq!(w.len(), 4 * cube.positions.len());
        for (v, (p, nrm)) in w.iter().zip(cube.positions.iter().cycle().zip(cube.normals.iter().cycle())) {
            assert!(v.valid);
            assert!((v.position.y - s * p.y).abs() < 1e-5);
            // Aligned, x is the offset along the outward curve normal; else along +x.
            let (centre_dist, radius) = if aligned {
                (Vec2::new(v.position.x, v.position.z).length(), 0.5 + s * p.x)
            } else {
                (Vec2::new(v.position.x - s * p.x, v.position.z).length(), 0.5)
            };
            // The Bezier circle's radius error is 2.7e-4 of the radius.
            assert!((centre_dist - radius).abs() < 3e-4, "aligned {aligned}: {centre_dist} vs {radius}");
            if aligned && nrm.x.abs() > 0.5 {
                let radial = Vec3::new(v.position.x, 0.0, v.position.z).normalize() * nrm.x.signum();
                assert!(v.normal.dot(radial) > 0.999, "side faces point along the curve normal: {:?}", v.normal);
            }
        }
    }
}

/// The arc-length stretch in the normals: a ramp y = k z carried along a straight curve whose
/// repetition is L world units long (z extent 1, height scale s) has world slope s k / L.
#[test]
fn curve_attachment_normals_include_the_arc_length_stretch() {
    let (m, _) = matrix(&geometry::plane(2.0, 4, 4).unwrap(), 64, F32, 0);
    let (s, k) = (0.05f32, 2.0f32);
    // Along +v: x goes across the curve (t_u, eq. 9, and n_c, eq. 10, agree here).
    let a = Vec2::new(0.5, 0.2);
    let line = [a, a + Vec2::new(0.0, 0.1), a + Vec2::new(0.0, 0.2), a + Vec2::new(0.0, 0.3)];
    // The whole curve, 0.3 UV = 0.6 world units, is one repetition.
    let inst = InstanceData::identity()
        .with_tan(glam::Mat4::from_scale(Vec3::splat(s)))
        .with_curve(&line, 0.0, 1.0, -0.5, 0.5);
    let ramp = tilted_tile(0.0, k, 2);
    for aligned in [false, true] {
        let w = warp_gpu(m.clone(), &ramp, curve_settings(aligned), vec![inst]);
        // The curve runs along +v = world z, so the ramp rises along z.
        let slope = s * k / 0.6;
        let expected = Vec3::new(0.0, 1.0, -slope).normalize();
        for v in &w {
            assert!(v.valid);
            assert!(
                degrees(v.normal, expected) < 0.2,
                "aligned {aligned}: normal tilts {} deg, not {}",
                degrees(v.normal, Vec3::Y),
                degrees(expected, Vec3::Y)
            );
        }
    }
}

/// Eqs. 11-12: with gravity, every hair vertex keeps its distance to its foot p_s, the hairs
/// hang down, and normals bend with them (perpendicular to the bent strand).
#[test]
fn fur_gravity_keeps_each_vertex_at_its_distance_to_its_foot() {
    let r = 0.5f32;
    let (m, texels) = matrix(&geometry::cylinder(r, 1.0, 256, 4).unwrap(), 128, F32, 0);
    // A hair card in the local x-y plane (normal +z), 16 segments up to y = 1.
    let rows = 16u32;
    let (mut p, mut uv, mut idx) = (Vec::new(), Vec::new(), Vec::new());
    for j in 0..=rows {
        for x in [-0.5f32, 0.5] {
            p.push(Vec3::new(x, j as f32 / rows as f32, 0.0));
            uv.push(Vec2::new(x + 0.5, j as f32 / rows as f32));
        }
    }
    for j in 0..rows {
        let a = 2 * j;
        idx.extend_from_slice(&[a, a + 1, a + 2, a + 1, a + 3, a + 2]);
    }
    let count = p.len();
    let card = Mesh::from_parts(p, Some(vec![Vec3::Z; count]), uv, idx, vec![]).unwrap();
    let (u, v, scale, c) = (0.25f32, 0.5f32, 0.05f32, 10.0f32);
    let inst = point_instance(&Placement { piece: 0, u, v, angle: 0.0, scale: 1.0 }, scale, 1.0, 0.0, 0.0);
    let s = WarpSettings { mode: WarpMode::Point, gravity: c, min_weight: 0.5 };
    let w = warp_gpu(m, &card, s, vec![inst]);
    // At u = 0.25 the cloth normal is +x, t_u = -z, t_v = -y (down).
    let a = u * TAU;
    let (n, tu, tv) = (Vec3::new(a.sin(), 0.0, a.cos()), Vec3::new(a.cos(), 0.0, -a.sin()), -Vec3::Y);
    // The surface point from the matrix texture (within 1.5e-4 of n r, the chord sagitta).
    let origin = texels.lookup(Vec2::new(u, v), 0.5).unwrap().p;
    assert!((origin - n * r).length() < 2e-4);
    let mut lowest = 0.0f32;
    for (k, (wv, q)) in w.iter().zip(&card.positions).enumerate() {
        assert!(wv.valid);
        let q = *q * scale;
        let foot = origin + tu * q.x + tv * q.z;
        let d = (wv.position - foot).length();
        assert!((d - q.y).abs() < 1e-5, "vertex {k}: {d} from its foot, not {}", q.y);
        lowest = lowest.min(wv.position.y);
        // The strand's direction here (central difference along the card) is perpendicular to the normal.
        let (j, side) = (k / 2, k % 2);
        if j > 0 && j < rows as usize {
            let along = (w[2 * (j + 1) + side].position - w[2 * (j - 1) + side].position).normalize();
            assert!(
                wv.normal.dot(along).abs() < 0.02,
                "vertex {k}: normal {:?} along the bent hair {along:?}",
                wv.normal
            );
        }
    }
    assert!(lowest < -0.02, "the hairs hang down ({lowest})");
}

/// A decal's angle (and so its spin) turns its normals: a ridge y = k x in a decal of UV size
/// `size` on a plane of side 1 through height H has world slope H k / size along the turned x.
#[test]
fn decal_rotation_turns_the_normals() {
    use werkstatt::nodes::warp::attach::area_tex;
    let (m, _) = matrix(&geometry::plane(1.0, 4, 4).unwrap(), 64, F32, 0);
    let (k, size, height) = (0.5f32, 0.2f32, 0.1f32);
    let ridge = tilted_tile(k, 0.0, 2);
    let (lo, hi) = ridge.bounds();
    let slope = height * k / size;
    for angle in [0.0f32, 30.0, 90.0] {
        let inst = InstanceData::identity()
            .with_tex(area_tex(lo, hi, true, Vec2::splat(0.5), size, angle))
            .with_tan(glam::Mat4::from_scale(Vec3::new(1.0, height, 1.0)));
        let w = warp_gpu(m.clone(), &ridge, AREA, vec![inst]);
        let x = Vec3::new(angle.to_radians().cos(), 0.0, angle.to_radians().sin());
        let expected = (Vec3::Y - x * slope).normalize();
        for v in &w {
            assert!(v.valid);
            assert!(degrees(v.normal, expected) < 0.2, "angle {angle}: normal {:?}, expected {expected:?}", v.normal);
        }
    }
}

/// Eq. 6 scales the whole geometry: a 2:1 decal stays 2:1 (its longer side is `size`).
#[test]
fn decals_keep_their_aspect_ratio() {
    use werkstatt::nodes::warp::attach::area_tex;
    let (lo, hi) = (Vec3::new(-1.0, 0.0, -0.5), Vec3::new(1.0, 0.0, 0.5));
    let t = area_tex(lo, hi, true, Vec2::splat(0.5), 0.2, 0.0);
    let (a, b) = (t.transform_point2(Vec2::new(lo.x, lo.z)), t.transform_point2(Vec2::new(hi.x, hi.z)));
    assert!(((b - a) - Vec2::new(0.2, 0.1)).length() < 1e-6, "{a} {b}");
    assert!(((a + b) * 0.5 - Vec2::splat(0.5)).length() < 1e-6, "centred: {a} {b}");
    // Tiles fill their square cell.
    let t = area_tex(lo, hi, false, Vec2::splat(0.5), 0.2, 0.0);
    let (a, b) = (t.transform_point2(Vec2::new(lo.x, lo.z)), t.transform_point2(Vec2::new(hi.x, hi.z)));
    assert!(((b - a) - Vec2::splat(0.2)).length() < 1e-6, "{a} {b}");
}

/// A degenerate curve end (control point = end point, common in SVG): the direction there is
/// the tangent's limit, c3 - c1 at t = 1 (not c2 - c0).
#[test]
fn degenerate_curve_ends_take_the_tangent_limit() {
    use werkstatt::warp::curve_direction;
    let c = [Vec2::ZERO, Vec2::new(1.0, 0.0), Vec2::new(2.0, 1.0), Vec2::new(2.0, 1.0)];
    let end = curve_direction(&c, 1.0);
    let near = werkstatt::warp::bezier_tangent(&c, 0.9999).normalize();
    assert!(end.dot(near) > 0.9999, "{end} vs {near}");
    let c = [Vec2::ZERO, Vec2::ZERO, Vec2::new(1.0, 2.0), Vec2::new(3.0, 2.0)];
    let start = curve_direction(&c, 0.0);
    let near = werkstatt::warp::bezier_tangent(&c, 1e-4).normalize();
    assert!(start.dot(near) > 0.9999, "{start} vs {near}");
}

/// The orientation filter never mixes pieces: a piece next to a differently oriented one
/// (gutter 0.1 UV = 6.4 texels, radius 8) keeps its constant frames exactly.
#[test]
fn the_orientation_filter_leaves_other_pieces_untouched() {
    let mesh = sewn_plane(false);
    let (_, raw) = matrix(&mesh, 64, F32, 0);
    let (_, smooth) = matrix(&mesh, 64, F32, 8);
    let mut checked = 0;
    for (a, b) in raw.frames.iter().zip(&smooth.frames) {
        if a.n.length_squared() < 0.25 {
            continue;
        }
        // Each piece is flat with one frame: filtering within it changes nothing.
        assert!((a.tu - b.tu).length() < 1e-5 && (a.tv - b.tv).length() < 1e-5, "{a:?} became {b:?}");
        checked += 1;
    }
    assert!(checked > 1000, "{checked}");
}

fn graph(text: &str) -> werkstatt::core::graph::Graph {
    werkstatt::core::graph::Graph::load_str(text, "test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}"))
}

fn matrix_output(ev: &werkstatt::core::eval::Evaluator, node: &str) -> Arc<werkstatt::warp::MatrixTexture> {
    match ev.output(node, "matrix") {
        Some(werkstatt::core::port::Value::MatrixTexture(m)) => m.clone(),
        _ => panic!("no matrix texture on {node}"),
    }
}

/// A mirrored UV island is counted and warned on the node, with what it affects and how to
/// silence it; `flip_left_handed` makes its frames right-handed, `mirrored_ok` quiets it.
#[test]
fn a_left_handed_island_is_warned_and_can_be_flipped() {
    let mirrored = |flip: bool, ok: bool| {
        graph(&format!(
            r#"(version: 1, nodes: {{
                "m": (kind: "MeshFile", params: {{"path": "tests/data/mirrored_piece.obj", "normalize": false}}),
                "mt": (kind: "MatrixTexture", params: {{"resolution": 64, "flip_left_handed": {flip}, "mirrored_ok": {ok}}}),
                "out": (kind: "Watch"),
            }}, links: [("m.surface", "mt.surface"), ("mt.min_resolution", "out.value")])"#
        ))
    };
    let quiet = common::run_graph(&mirrored(false, true), 8, 8);
    assert!(quiet.report("mt").unwrap().warnings.is_empty(), "mirrored_ok silences the warning");
    for flip in [false, true] {
        let ev = common::run_graph(&mirrored(flip, false), 8, 8);
        let warnings = ev.report("mt").unwrap().warnings.to_vec();
        // Piece 1 covers a quarter of UV space: 1024 of 4096 texels.
        assert!(
            warnings
                .iter()
                .any(|w| w.contains("about 1024 texels have left-handed") && w.contains("piece 1: 1024 of 1024")),
            "{warnings:?}"
        );
        if !flip {
            assert!(
                warnings.iter().any(|w| w.contains("read backwards") && w.contains("set mirrored_ok")),
                "the warning says what it affects and how to silence it: {warnings:?}"
            );
        }
        let texels = read_matrix(common::gpu(), &matrix_output(&ev, "mt")).unwrap();
        let (mut right, mut left) = (0, 0);
        for t in texels.frames.iter().filter(|t| t.n.length_squared() > 0.25) {
            if t.tu.cross(t.n).dot(t.tv) > 0.0 { right += 1 } else { left += 1 }
        }
        if flip {
            assert_eq!(left, 0, "flipped: every frame right-handed ({right} right)");
        } else {
            assert!((900..1100).contains(&left), "{left} left-handed texels");
        }
    }
}

/// A surface moved by MatrixTexture's model transform (as the Draw that shows it) carries its
/// attachments: a point attached at (u, v) sits at the moved surface point.
#[test]
fn a_moved_surface_carries_its_attachments() {
    let g = graph(
        r#"(version: 1, nodes: {
            "p": (kind: "Primitive", params: {"shape": "plane", "size": 2.0}),
            "mt": (kind: "MatrixTexture", params: {"resolution": 32, "translate": [1.0, 2.0, 3.0], "rotate": [0.0, 90.0, 0.0]}),
            "out": (kind: "Watch"),
        }, links: [("p.mesh", "mt.surface"), ("mt.min_resolution", "out.value")])"#,
    );
    let ev = common::run_graph(&g, 8, 8);
    let model = glam::Mat4::from_rotation_translation(
        glam::Quat::from_rotation_y(90f32.to_radians()),
        Vec3::new(1.0, 2.0, 3.0),
    );
    let detail = geometry::cube(1.0).unwrap();
    let (u, v, scale) = (0.3f32, 0.6f32, 0.1f32);
    let inst = point_instance(&Placement { piece: 0, u, v, angle: 0.0, scale: 1.0 }, scale, 1.0, 0.0, 0.0);
    let w = warp_gpu(matrix_output(&ev, "mt"), &detail, POINT, vec![inst]);
    for (wv, q) in w.iter().zip(&detail.positions) {
        assert!(wv.valid);
        // On the unmoved plane of side 2: (2 (u - 0.5), 0, 2 (v - 0.5)) + scale q.
        let expected = model.transform_point3(Vec3::new(2.0 * (u - 0.5), 0.0, 2.0 * (v - 0.5)) + *q * scale);
        assert!((wv.position - expected).length() < 1e-4, "{:?} vs {expected:?}", wv.position);
    }
}

/// The plane of `a_moved_surface_carries_its_attachments` drawn by a Draw with `draw_params`,
/// buttons on it through a MatrixTexture with `matrix_params` (linked to the Draw's scene when
/// `drawn`), into a G-buffer.
fn drawn_plane(draw_params: &str, matrix_params: &str, drawn: bool) -> werkstatt::core::graph::Graph {
    let drawn_link = if drawn { r#"("d.scene", "mt.drawn"),"# } else { "" };
    graph(&format!(
        r#"(version: 2, nodes: {{
            "p": (kind: "Primitive", params: {{"shape": "plane", "size": 2.0}}),
            "d": (kind: "Draw", params: {{{draw_params}}}),
            "mt": (kind: "MatrixTexture", params: {{"resolution": 32, {matrix_params}}}),
            "button": (kind: "Primitive", params: {{"shape": "box", "size": 0.1}}),
            "grid": (kind: "GridPlacement", params: {{"columns": 2, "rows": 2}}),
            "attach": (kind: "PointAttachment"),
            "all": (kind: "Merge"),
            "cam": (kind: "OrbitCamera"),
            "g": (kind: "GBufferPass"),
            "out": (kind: "Preview"),
        }}, links: [("p.mesh", "d.mesh"), ("p.mesh", "mt.surface"), {drawn_link}
            ("mt.matrix", "attach.matrix"), ("button.mesh", "attach.mesh"), ("grid.placements", "attach.placements"),
            ("d.scene", "all.a"), ("attach.scene", "all.b"), ("all.scene", "g.scene"), ("cam.camera", "g.camera"),
            ("g.depth", "out.image")])"#
    ))
}

fn failure(ev: &werkstatt::core::eval::Evaluator, node: &str) -> Option<String> {
    match ev.report(node).unwrap().status {
        werkstatt::core::eval::NodeStatus::Failed(m) => Some(m.clone()),
        _ => None,
    }
}

/// One transform per attached surface: linked to the Draw's scene, the matrix texture takes
/// the Draw's transform (the attachments sit on the moved surface); a second transform that
/// disagrees is an error on MatrixTexture, and a MatrixTexture left behind by its Draw's
/// transform is an error on the G-buffer pass, both naming the two transforms.
#[test]
fn a_matrix_texture_takes_its_transform_from_the_draw() {
    let moved = r#""translate": [1.0, 2.0, 3.0], "rotate": [0.0, 90.0, 0.0]"#;
    let ev = common::run_graph(&drawn_plane(moved, "", true), 16, 16);
    let model = glam::Mat4::from_rotation_translation(
        glam::Quat::from_rotation_y(90f32.to_radians()),
        Vec3::new(1.0, 2.0, 3.0),
    );
    let detail = geometry::cube(1.0).unwrap();
    let inst = point_instance(&Placement { piece: 0, u: 0.3, v: 0.6, angle: 0.0, scale: 1.0 }, 0.1, 1.0, 0.0, 0.0);
    let w = warp_gpu(matrix_output(&ev, "mt"), &detail, POINT, vec![inst]);
    for (wv, q) in w.iter().zip(&detail.positions) {
        let expected = model.transform_point3(Vec3::new(2.0 * (0.3 - 0.5), 0.0, 2.0 * (0.6 - 0.5)) + *q * 0.1);
        assert!(wv.valid && (wv.position - expected).length() < 1e-4, "{:?} vs {expected:?}", wv.position);
    }
    // The same transform given twice is allowed; a different one is not.
    let ev = common::run_graph(&drawn_plane(moved, moved, true), 16, 16);
    assert!(failure(&ev, "mt").is_none());
    let ev = common::evaluate_graph(&drawn_plane(moved, r#""translate": [1.0, 2.0, 0.0]"#, true), 16, 16);
    let m = failure(&ev, "mt").expect("disagreeing transforms fail");
    assert!(
        m.contains("two transforms disagree") && m.contains("translate [1, 2, 0]") && m.contains("translate [1, 2, 3]"),
        "{m}"
    );
    // Without the link, the G-buffer pass sees the attachments leave their surface.
    let ev = common::evaluate_graph(&drawn_plane(moved, "", false), 16, 16);
    let m = failure(&ev, "g").expect("attachments off their surface fail");
    assert!(m.contains("translate [0, 0, 0]") && m.contains("translate [1, 2, 3]") && m.contains("`drawn`"), "{m}");
    let ev = common::evaluate_graph(&drawn_plane(moved, moved, false), 16, 16);
    assert!(failure(&ev, "g").is_none(), "equal transforms given twice still draw");
}

/// A placement file's rows in piece-local coordinates land at the same spot of each piece's
/// UV rectangle; read as atlas coordinates, the rows whose piece column disagrees are warned.
#[test]
fn placement_files_honour_the_piece_column() {
    let layout = |coordinates: &str| {
        let g = graph(&format!(
            r#"(version: 1, nodes: {{
                "m": (kind: "MeshFile", params: {{"path": "tests/data/mirrored_piece.obj", "normalize": false}}),
                "pf": (kind: "PlacementFile", params: {{"path": "tests/data/piece_layout.csv", "coordinates": "{coordinates}"}}),
                "out": (kind: "Watch"),
            }}, links: [("m.surface", "pf.surface"), ("pf.count", "out.value")])"#
        ));
        let ev = common::run_graph(&g, 8, 8);
        let warnings = ev.report("pf").unwrap().warnings.to_vec();
        match ev.output("pf", "placements") {
            Some(werkstatt::core::port::Value::Instances(p)) => ((**p).clone(), warnings),
            _ => panic!("no placements"),
        }
    };
    // Piece 0 covers u 0-0.5, v 0-1; piece 1 (mirrored) u 0.5-1, v 0-0.5 (OBJ v is flipped on load).
    let (p, warnings) = layout("piece");
    assert!(warnings.is_empty(), "{warnings:?}");
    let got: Vec<(u32, f32, f32)> = p.iter().map(|p| (p.piece, p.u, p.v)).collect();
    assert_eq!(got, [(0, 0.25, 0.5), (1, 0.75, 0.25)]);
    // As atlas UVs (0.5, 0.5) lies on the pieces' shared corner region: the piece column of at
    // least one row disagrees with the piece found there, and the node says so.
    let (p, warnings) = layout("atlas");
    assert_eq!(p.len(), 2);
    assert!(warnings.iter().any(|w| w.contains("1 rows name a piece other than")), "{warnings:?}");
}

/// The sampling-theorem minimum (2 texels across the shortest UV edge) is a warning on the
/// node, not only a log line.
#[test]
fn the_sampling_minimum_is_warned_on_the_node() {
    let g = graph(
        r#"(version: 1, nodes: {
            "p": (kind: "Primitive", params: {"shape": "plane", "segments_u": 64, "segments_v": 4}),
            "mt": (kind: "MatrixTexture", params: {"resolution": 32}),
            "out": (kind: "Watch"),
        }, links: [("p.mesh", "mt.surface"), ("mt.min_resolution", "out.value")])"#,
    );
    let ev = common::run_graph(&g, 8, 8);
    let warnings = ev.report("mt").unwrap().warnings.to_vec();
    assert!(warnings.iter().any(|w| w.contains("resolution 32 is below the sampling minimum 128")), "{warnings:?}");
}
