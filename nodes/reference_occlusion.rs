//! `ReferenceOcclusion`: ray-traced ambient occlusion of the G-buffer's pixels against the
//! whole scene on the CPU (a BVH of every triangle, obvhs), to measure SSAO and hybrid
//! occlusion against instead of judging them by eye.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use glam::{Vec2, Vec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::ray::Ray;
use obvhs::triangle::Triangle;

use crate::core::node::prelude::*;
use crate::core::rng::SplitMix64;
use crate::gpu::{GpuImage, read_back};
use crate::render::scene::{DrawItem, GBuffer, View};

/// Ray origins are moved this far (world units) along the normal, off the surface they start on.
pub const ORIGIN_OFFSET: f32 = 1e-3;

pub static REFERENCE_OCCLUSION: NodeSpec = NodeSpec {
    kind: "ReferenceOcclusion",
    category: Category::Lighting,
    doc: "Ray-traced ambient occlusion (CPU) of the G-buffer's pixels against every triangle of the scene: per pixel, `samples` \
cosine-weighted rays about the G-buffer normal from the reconstructed world position (moved 0.001 along the normal); a ray is occluded \
when it hits a triangle within `max_distance` (world units, the counterpart of Ssao's radius). Output: the unoccluded fraction \
(1 = unoccluded, the cosine-weighted visibility), Rgba32Float. Rays follow a rank-1 (R2) sequence rotated per pixel by a hash of \
the pixel and `seed`, so the same input gives the same bytes, whatever the thread count. Plain meshes only: deferred-warped \
attachments are not traced. Slow (seconds); meant for tests and benches.",
    inputs: &[
        PortSpec::required("scene", PortType::Scene, "The geometry that occludes (every triangle, world space)."),
        PortSpec::required("gbuffer", PortType::GBuffer, "The pixels: positions from its depth and view, its normals."),
    ],
    outputs: &[PortSpec::output(
        "occlusion",
        PortType::Texture,
        "The visibility factor in rgb (1 = unoccluded), Rgba32Float.",
    )],
    params: &[
        ParamSpec::new("samples", ParamKind::Int { default: 256, min: 1, max: 65536 }, "Rays per pixel."),
        ParamSpec::new(
            "max_distance",
            ParamKind::Float { default: 1.0, min: 1e-4, max: 1e6 },
            "Hits farther than this (world units) do not occlude.",
        ),
        ParamSpec::new("seed", ParamKind::Int { default: 0, min: 0, max: 1 << 31 }, "Seed of the ray directions."),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(ReferenceOcclusionNode),
};

/// The world triangles of the plain meshes of `items` in a BVH.
pub struct SceneBvh {
    tris: Vec<Triangle>,
    bvh: Option<CwBvh>,
}

impl SceneBvh {
    pub fn new(items: &[DrawItem]) -> SceneBvh {
        let mut tris = Vec::new();
        for item in items.iter().filter(|i| i.kind.places_mesh()) {
            let p: Vec<Vec3A> = item.mesh.positions.iter().map(|&p| item.model.transform_point3(p).into()).collect();
            for t in item.mesh.indices.chunks_exact(3) {
                tris.push(Triangle { v0: p[t[0] as usize], v1: p[t[1] as usize], v2: p[t[2] as usize] });
            }
        }
        let bvh = (!tris.is_empty())
            .then(|| build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Duration::default()));
        SceneBvh { tris, bvh }
    }

    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// Whether a ray from `origin` along unit `dir` hits a triangle within `max_distance`.
    pub fn occluded(&self, origin: Vec3, dir: Vec3, max_distance: f32) -> bool {
        let Some(bvh) = &self.bvh else { return false };
        let ray = Ray::new(origin.into(), dir.into(), 0.0, max_distance);
        !bvh.ray_traverse_miss(ray, |r, id| self.tris[bvh.primitive_indices[id] as usize].intersect(r))
    }

    /// The cosine-weighted visibility at `point` with unit normal `normal`: the fraction of
    /// `samples` rays that hit nothing within `max_distance`. `stream` picks the rotation of
    /// the ray sequence (one per pixel and seed).
    pub fn visibility(&self, point: Vec3, normal: Vec3, samples: u32, max_distance: f32, stream: u64) -> f32 {
        let mut rng = SplitMix64::new(stream);
        let shift = Vec2::new(rng.next_f32(), rng.next_f32());
        // The R2 sequence (Roberts 2018): the plastic number's rank-1 lattice.
        const G: f32 = 1.324_718;
        let alpha = Vec2::new(1.0 / G, 1.0 / (G * G));
        let (t, b) = normal.any_orthonormal_pair();
        let origin = point + normal * ORIGIN_OFFSET;
        let mut open = 0u32;
        for k in 0..samples {
            let u = (shift + alpha * (k as f32 + 0.5)).fract();
            // Cosine-weighted: a uniform disc point lifted onto the hemisphere.
            let (r, phi) = (u.x.sqrt(), u.y * std::f32::consts::TAU);
            let dir = t * (r * phi.cos()) + b * (r * phi.sin()) + normal * (1.0 - u.x).max(0.0).sqrt();
            if !self.occluded(origin, dir.normalize(), max_distance) {
                open += 1;
            }
        }
        open as f32 / samples.max(1) as f32
    }
}

/// The settings of [`reference_occlusion`].
#[derive(Clone, Copy, Debug)]
pub struct ReferenceSettings {
    pub samples: u32,
    pub max_distance: f32,
    pub seed: u64,
}

/// The world position of G-buffer pixel (x, y) at linear view depth `d`.
pub fn world_position(view: &View, x: u32, y: u32, d: f32) -> Vec3 {
    let (w, h) = (view.width as f32, view.height as f32);
    let ndc = Vec2::new((x as f32 + 0.5) / w * 2.0 - 1.0, 1.0 - (y as f32 + 0.5) / h * 2.0);
    let p = view.proj;
    let v = Vec3::new((ndc.x + p.z_axis.x) * d / p.x_axis.x, (ndc.y + p.z_axis.y) * d / p.y_axis.y, -d);
    view.inv_view.transform_point3(v)
}

/// Per pixel (row-major) the visibility of the point at `depth` (0: nothing, visibility 1)
/// with normal `normals`, traced against `bvh` on all cores.
pub fn reference_occlusion(
    bvh: &SceneBvh,
    view: &View,
    depth: &[f32],
    normals: &[Vec3],
    s: &ReferenceSettings,
) -> Vec<f32> {
    let (w, h) = (view.width as usize, view.height as usize);
    let next = AtomicUsize::new(0);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(h.max(1));
    let rows: Vec<(usize, Vec<f32>)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let y = next.fetch_add(1, Ordering::Relaxed);
                        if y >= h {
                            break done;
                        }
                        let row = (0..w)
                            .map(|x| {
                                let i = y * w + x;
                                let (d, n) = (depth[i], normals[i]);
                                if d <= 0.0 || !n.is_finite() || n.length_squared() < 1e-8 {
                                    return 1.0;
                                }
                                let p = world_position(view, x as u32, y as u32, d);
                                let stream = s.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (i as u64).wrapping_add(1);
                                bvh.visibility(p, n.normalize(), s.samples, s.max_distance, stream)
                            })
                            .collect();
                        done.push((y, row));
                    }
                })
            })
            .collect();
        workers.into_iter().flat_map(|t| t.join().expect("a ray-tracing thread panicked")).collect()
    });
    let mut out = vec![1.0; w * h];
    for (y, row) in rows {
        out[y * w..(y + 1) * w].copy_from_slice(&row);
    }
    out
}

struct ReferenceOcclusionNode;

impl Node for ReferenceOcclusionNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let scene: Arc<Vec<DrawItem>> = cx.input("scene")?;
        let g: Arc<GBuffer> = cx.input("gbuffer")?;
        let settings = ReferenceSettings {
            samples: cx.int("samples").max(1) as u32,
            max_distance: cx.f32("max_distance"),
            seed: cx.int("seed") as u64,
        };
        let depth = read_back(gpu, &g.depth)?;
        let normal = read_back(gpu, &g.normal)?;
        let dc = (depth.rgba.len() / (depth.width * depth.height) as usize).max(1);
        let nc = (normal.rgba.len() / (normal.width * normal.height) as usize).max(1);
        let depth: Vec<f32> = depth.rgba.iter().step_by(dc).copied().collect();
        let normals: Vec<Vec3> = normal.rgba.chunks_exact(nc).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        let bvh = SceneBvh::new(&scene);
        let mut view = g.view;
        (view.width, view.height) = (g.width(), g.height());
        let vis = reference_occlusion(&bvh, &view, &depth, &normals, &settings);
        let texels: Vec<f32> = vis.iter().flat_map(|&v| [v, v, v, 1.0]).collect();
        let out = GpuImage::upload(
            gpu,
            "reference occlusion",
            g.width(),
            g.height(),
            wgpu::TextureFormat::Rgba32Float,
            16,
            bytemuck::cast_slice(&texels),
        );
        cx.set("occlusion", Arc::new(out));
        Ok(())
    }
}
