//! Deferred warping against analytic ground truth: matrix textures of a plane, a cylinder and
//! a sphere; warped vertices through the GPU export path against the analytic surface frame
//! and against the CPU reference; no shear on sheared UVs; outliers discarded.
//! Tolerances are stated relative to the world size of one texel.

use std::f32::consts::{PI, TAU};
use std::sync::Arc;

use glam::{Vec2, Vec3};
use werkstatt::mesh::Mesh;
use werkstatt::nodes::attach::point_instance;
use werkstatt::nodes::export::GpuWarper;
use werkstatt::nodes::geometry;
use werkstatt::nodes::matrix_texture::{MatrixTextureNode, read_matrix};
use werkstatt::warp::{AttachedDraw, InstanceData, MatrixTexels, Placement, WarpMode, WarpSettings, warp_all_cpu};

use crate::common;

const F32: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

fn matrix(
    mesh: &Mesh,
    res: u32,
    format: wgpu::TextureFormat,
    filter: u32,
) -> (Arc<werkstatt::warp::MatrixTexture>, MatrixTexels) {
    let gpu = common::gpu();
    let m = MatrixTextureNode::default().render(gpu, mesh, res, format, filter).unwrap();
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
            vec![point_instance(&Placement { piece: 0, u: 0.3, v: 0.4, angle: 30.0, scale: 1.0 }, 0.1, 2.0, 0.0, 0.0)],
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
            let cpu = warp_all_cpu(&texels, &s, &detail, &instances);
            // Equal lengths, and something valid: an empty or all-outlier GPU result must fail.
            assert_eq!(gpu.len(), instances.len() * detail.positions.len(), "{mode:?}");
            assert_eq!(gpu.len(), cpu.len(), "{mode:?}");
            assert!(gpu.iter().any(|g| g.valid), "{mode:?}: no valid vertex");
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
        assert!((frame.p.x - x).abs() < 0.25 / res as f32 * 2.5, "u = {u}: x {} vs {x}", frame.p.x);
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
    use werkstatt::nodes::cloth::{FlagParams, Preset, SkirtParams};
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
