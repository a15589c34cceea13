//! `ShadowAtlas`: variance shadow maps of many directional lights in one texture (dissertation
//! §4.2.1, Fig. 4.11), one tile per median-cut light, for the
//! visibility term VIS_i of eq. 3.43 (`IblShading`'s `shadows` input).
//!
//! Choices the text leaves open, and what this node does:
//!
//! - **Layout**: a grid of `tile_size` x `tile_size` tiles, `ceil(sqrt(N))` columns, tile i at
//!   column i mod columns, row i / columns. Each tile has a guard band of `guard` texels per
//!   side; the light's projection maps the scene into the tile's inner square and extends
//!   into the guard band, so the guard holds real geometry (the blur reads it).
//! - **Frustum**: orthographic along -direction, fitted to the bounding sphere (centre c,
//!   radius R) of the drawn items' transformed mesh bounds: the inner square spans [-R, R]
//!   across, depth [0, 1] spans 2R (near plane R in front of c, far plane R behind it).
//!   With a camera linked (issue 34), the inner square is instead the smallest one around the
//!   visible receivers, the scene's box clipped to the view frustum (src/ibl/shadow_fit.rs),
//!   centred on whole texels; the depth range stays 2R, so every caster is in it.
//! - **Drawing**: `SceneDrawer::depth_tiles`, one instanced draw per batch of <= 64 lights,
//!   then a moments pass writes (c, c^2) of the centred depth c = d - 1/2 (Rg16Float) and a separable Gaussian blurs each
//!   tile; more than 64 lights draw batch by batch into a batch texture whose tiles are
//!   copied into the atlas.
//! - **Blur width** (an area light of the region's size): the region's solid angle Omega is a
//!   cone of angular radius theta = acos(1 - Omega / 2 pi); an occluder at the reference
//!   distance d_ref = 0.25 R above its receiver casts a penumbra of half-width
//!   tan(theta) d_ref, so sigma = blur_scale tan(theta) d_ref / texel (texel = 2R / inner
//!   tile width, world units), clamped so that 3 sigma <= guard. The blur's taps are clamped
//!   to the tile (guard included): it never reads another tile.
//! - **Guard**: `guard` = -1 derives it: ceil(3 sigma_max), sigma_max the widest unclamped
//!   sigma (at texel 2R / tile_size) among the lights carrying at least the mean energy
//!   (regions over dark parts of a map are huge but nearly black: they take the clamp), at
//!   most tile_size / 8. An explicit guard is at most tile_size / 4.

use std::sync::Arc;

use glam::{Mat4, Vec2, Vec3, Vec4};

use crate::core::node::prelude::*;
use crate::gpu::{Bind, FullscreenPass, GpuContext, GpuImage, TextureDesc};
use crate::ibl::gpu::Lights;
use crate::ibl::shadow_fit::{
    allocate_and_pack, box_corners, frustum_corners, intersection_points, pack_tiles, receiver_square,
};
use crate::render::draw::{MAX_TILES, SceneDrawer, Tile};
use crate::render::scene::{Camera, DrawItem, View, scene_box};

/// The reference occluder-receiver distance of the blur rule, as a fraction of the scene's
/// bounding radius.
pub const REFERENCE_DISTANCE: f32 = 0.25;
/// The most lights one atlas holds (batches of 64).
pub const MAX_LIGHTS: usize = 1024;

pub static SHADOW_ATLAS: NodeSpec = NodeSpec {
    kind: "ShadowAtlas",
    category: Category::Lighting,
    doc: "Variance shadow maps of many directional lights (one per median-cut region) in one atlas texture (Fig. 4.11), for IblShading's \
visibility term (eq. 3.43). Per light an orthographic view along -direction fitted to the bounding sphere (c, R) of the drawn items; \
the inner tile (tile minus `guard` texels per side) spans [-R, R], the guard band holds real geometry. With a camera linked, each \
inner tile spans only the visible receivers (the scene's box clipped to the view frustum; depth still 2R), so a 64-texel tile shows contact shadows. Depth drawn with one instanced \
draw per batch of 64 lights, moments (c, c^2) of the centred depth c = d - 1/2 in Rg16Float (finer half floats near the scene), then a separable Gaussian per tile whose sigma models an area light of \
the region's solid angle Omega: theta = acos(1 - Omega / 2pi), sigma = blur_scale tan(theta) 0.25 R / texel, clamped to 3 sigma <= guard; \
taps are clamped to the tile, so no blur reads another tile. Memory: atlas texels x 4 bytes (Table 5.1: N x res^2 x 4 B).",
    inputs: &[
        PortSpec::required(
            "scene",
            PortType::Scene,
            "The occluders: coarse items, and detail items (attachments) unless coarse_only is on or they are over detail_triangle_budget.",
        ),
        PortSpec::required("lights", PortType::Lights, "Directional lights (MedianCut), one tile each."),
        PortSpec::optional(
            "camera",
            PortType::Camera,
            "When linked (and fit_to_view is on), each tile spans only the receivers the camera sees: the scene's box clipped to the view frustum, so its texels are spent where they show; casters keep the whole scene's depth range.",
        ),
    ],
    outputs: &[
        PortSpec::output("shadows", PortType::ShadowAtlas, "The atlas with each light's matrices and tile."),
        PortSpec::output(
            "atlas",
            PortType::Texture,
            "The atlas itself (Rg16Float moments of the centred depth d - 1/2), for inspection.",
        ),
        PortSpec::output("memory_mb", PortType::Scalar, "Atlas memory in MiB (texels x 4 bytes)."),
    ],
    params: &[
        ParamSpec::new(
            "tile_size",
            ParamKind::Int { default: 128, min: 16, max: 1024 },
            "Tile width and height in texels (guard band included); with sizes by_penumbra, the atlas holds the memory of N such tiles.",
        ),
        ParamSpec::new(
            "guard",
            ParamKind::Int { default: -1, min: -1, max: 256 },
            "Guard band per tile side in texels; -1 derives it: ceil(3 sigma) of the widest blur among lights with at least the mean energy, at most tile/8.",
        ),
        ParamSpec::new(
            "coarse_only",
            ParamKind::Bool { default: false },
            "Draw only coarse items (the simulation surface), not detail attachments (the dissertation's figures). Off: attachments cast too while their triangles stay within detail_triangle_budget.",
        ),
        ParamSpec::new(
            "detail_triangle_budget",
            ParamKind::Int { default: DETAIL_TRIANGLE_BUDGET as i64, min: 0, max: 1_000_000_000 },
            "With coarse_only off, the most detail triangles (all attachment instances together) that cast; above it only coarse items cast, with a warning naming the count. Each caster is drawn once per light, so the default 50 000 costs the atlas pass at most 50 000 x lights triangles (6.4 M at 128 lights).",
        ),
        ParamSpec::new(
            "sizes",
            ParamKind::Choice { default: "by_penumbra", options: TileSizes::OPTIONS },
            "by_penumbra: tile sizes in proportion to the texels each light's penumbra needs (2 per sigma), within the memory of uniform tiles (at most 64 lights; more get uniform tiles); uniform: every tile tile_size (the dissertation).",
        ),
        ParamSpec::new(
            "fit_to_view",
            ParamKind::Bool { default: true },
            "With a camera linked, fit each tile to the visible receivers; off: to the scene's bounding sphere (the dissertation).",
        ),
        ParamSpec::new(
            "blur_scale",
            ParamKind::Float { default: 1.0, min: 0.0, max: 16.0 },
            "Multiplies the blur width rule (0: no blur).",
        ),
        ParamSpec::new(
            "bleed_reduction",
            ParamKind::Float { default: 0.3, min: 0.0, max: 0.99 },
            "Light-bleeding reduction: VIS = linstep(b, 1, p_max).",
        ),
        ParamSpec::new(
            "min_variance",
            ParamKind::Float { default: 1e-5, min: 0.0, max: 1.0 },
            "Lower bound of the variance (depth units^2; depth spans 2R).",
        ),
        ParamSpec::new(
            "jitter",
            ParamKind::Float { default: 0.0, min: 0.0, max: 8.0 },
            "Noise-jittered lookup (Fig. 4.13): offset in texels from a tiled 4x4 hash per light; 0 = off.",
        ),
        ParamSpec::new(
            "normal_offset",
            ParamKind::Float { default: 1.0, min: 0.0, max: 16.0 },
            "Lookup point moved along the surface normal by this many texels (world size) against acne.",
        ),
        ParamSpec::new(
            "depth_bias",
            ParamKind::Float { default: 0.002, min: 0.0, max: 0.5 },
            "Receiver depth bias, as a fraction of the depth range 2R.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(ShadowAtlasNode::default()),
};

pub use crate::ibl::shadow::{ShadowAtlas, ShadowLight, VsmParams, light_view_proj, tile_view_proj};

crate::choice!(
    /// How tile sizes are chosen.
    pub enum TileSizes {
        /// In proportion to the texels each light's penumbra needs, within the memory of
        /// uniform tiles: a sun's sharp shadow gets a large tile, a wide sky region a small one.
        ByPenumbra = "by_penumbra",
        /// Every tile `tile_size` (the dissertation's layout).
        Uniform = "uniform",
    }
);

/// The default `detail_triangle_budget`: 40 buttons of a few hundred triangles cast (a few
/// thousand in all), a 10 000-button flag (about 2 M) does not.
pub const DETAIL_TRIANGLE_BUDGET: usize = 50_000;

/// Texels per sigma of a penumbra that a tile sized by penumbra aims at.
pub const TEXELS_PER_SIGMA: f32 = 2.0;

/// The geometry settings of an atlas (the node's parameters without the lookup ones).
#[derive(Clone, Copy, Debug)]
pub struct AtlasSettings {
    pub tile_size: u32,
    /// None: derived from the widest blur.
    pub guard: Option<u32>,
    pub coarse_only: bool,
    pub blur_scale: f32,
    pub sizes: TileSizes,
    /// The inverse view-projection of the camera the tiles are fitted to (None: every tile
    /// spans the scene's bounding sphere, the dissertation's layout).
    pub fit_view: Option<Mat4>,
}

/// The bounding sphere (centre, radius) of the items' transformed mesh bounds.
pub fn bounding_sphere(items: &[DrawItem]) -> (Vec3, f32) {
    match scene_box(items.iter()) {
        Some((lo, hi)) => ((lo + hi) / 2.0, ((hi - lo).length() / 2.0).max(1e-4)),
        None => (Vec3::ZERO, 1.0),
    }
}

/// The angular radius of a cone of solid angle `omega`.
pub fn cone_angle(omega: f32) -> f32 {
    (1.0 - omega / (2.0 * std::f32::consts::PI)).clamp(-1.0, 1.0).acos()
}

/// The blur's sigma in texels for a region of solid angle `omega`, before the guard clamp.
pub fn blur_sigma(omega: f32, radius: f32, texel_world: f32, blur_scale: f32) -> f32 {
    let theta = cone_angle(omega).min(1.4);
    blur_scale * theta.tan() * REFERENCE_DISTANCE * radius / texel_world
}

/// The map from a light's clip space to atlas coordinates of the tile `rect` (texels) in a
/// `width` x `height` atlas (NDC y up, texel rows down, as `depth_tiles` draws it).
pub fn clip_to_atlas(rect: [u32; 4], width: u32, height: u32) -> Mat4 {
    let (w, h) = (width as f32, height as f32);
    let [x, y, tw, th] = rect.map(|v| v as f32);
    Mat4::from_cols(
        Vec4::new(tw / (2.0 * w), 0.0, 0.0, 0.0),
        Vec4::new(0.0, -th / (2.0 * h), 0.0, 0.0),
        Vec4::new(0.0, 0.0, 1.0, 0.0),
        Vec4::new((x + tw / 2.0) / w, (y + th / 2.0) / h, 0.0, 1.0),
    )
}

/// Columns and rows of the atlas grid for `n` tiles.
pub fn grid(n: usize) -> (u32, u32) {
    let columns = (n as f64).sqrt().ceil().max(1.0) as u32;
    (columns, (n as u32).div_ceil(columns).max(1))
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct BlurUniform {
    /// Each tile's texels: x0, y0, x1, y1 (exclusive).
    rect: [[f32; 4]; MAX_TILES],
    sigma: [[f32; 4]; MAX_TILES / 4],
    /// x: tiles in this texture, y: direction (0 horizontal, 1 vertical).
    info: [f32; 4],
}

/// The passes of an atlas, kept between frames.
pub struct AtlasBuilder {
    drawer: SceneDrawer,
    moments: FullscreenPass,
    blur: FullscreenPass,
}

impl Default for AtlasBuilder {
    fn default() -> Self {
        AtlasBuilder {
            drawer: SceneDrawer::default(),
            moments: FullscreenPass::new("vsm.wgsl").with_fragment_entry("fs_moments"),
            blur: FullscreenPass::new("vsm_blur.wgsl").with_fragment_entry("fs_blur"),
        }
    }
}

/// The moments format: Rg16Float (Table 5.1's RG16F) where the device renders it.
fn moments_format(gpu: &GpuContext) -> wgpu::TextureFormat {
    gpu.formats().moments
}

impl AtlasBuilder {
    /// The separable per-tile Gaussian (shaders/ibl/vsm_blur.wgsl) of `src`: tile j, its texels
    /// `tiles[j].0` (x, y, width, height), blurred with sigma `tiles[j].1` (texels; at most 64
    /// tiles), taps clamped to the tile. Texels in no tile become far (0.5, 0.25: centred
    /// depth 1/2). Returns a new texture of the atlas format.
    pub fn blur(&mut self, gpu: &GpuContext, src: &GpuImage, tiles: &[([u32; 4], f32)]) -> anyhow::Result<GpuImage> {
        anyhow::ensure!(tiles.len() <= MAX_TILES, "one blur covers at most {MAX_TILES} tiles");
        let format = moments_format(gpu);
        let mut u: BlurUniform = bytemuck::Zeroable::zeroed();
        for (j, ([x, y, w, h], sigma)) in tiles.iter().enumerate() {
            u.rect[j] = [*x as f32, *y as f32, (x + w) as f32, (y + h) as f32];
            u.sigma[j / 4][j % 4] = *sigma;
        }
        let mut input = src;
        let mut outputs = Vec::new();
        for dir in [0.0, 1.0] {
            let out = GpuImage::target(gpu, "vsm blur", src.width, src.height, format);
            u.info = [tiles.len() as f32, dir, 0.0, 0.0];
            self.blur.draw(
                gpu,
                &[Bind::Uniform(bytemuck::bytes_of(&u)), Bind::Texture(input)],
                &[&out.view],
                &[format],
            )?;
            outputs.push(out);
            input = outputs.last().expect("pushed");
        }
        Ok(outputs.pop().expect("two passes"))
    }

    /// Draws the atlas of `lights` for `items` (all of them: filter coarse items before).
    pub fn build(
        &mut self,
        gpu: &GpuContext,
        items: &[DrawItem],
        lights: &Lights,
        s: &AtlasSettings,
        params: VsmParams,
    ) -> anyhow::Result<ShadowAtlas> {
        let n = lights.lights.len();
        anyhow::ensure!((1..=MAX_LIGHTS).contains(&n), "the atlas holds 1 to {MAX_LIGHTS} lights, not {n}");
        let t = s.tile_size.max(16);
        let (center, radius) = bounding_sphere(items);
        // Receivers: the scene's box clipped to the camera's frustum, when fitting to a view.
        let receivers = match (s.fit_view, scene_box(items.iter())) {
            (Some(inv_view_proj), Some((lo, hi))) => {
                intersection_points(&frustum_corners(inv_view_proj), &box_corners(lo, hi))
            }
            _ => Vec::new(),
        };
        // Each light's inner half width (world units) and its penumbra's sigma (world units).
        let squares: Vec<(Vec2, f32)> = lights
            .lights
            .iter()
            .map(|l| receiver_square(l.direction, center, radius, &receivers).unwrap_or((Vec2::ZERO, radius)))
            .collect();
        let halves: Vec<f32> = squares.iter().map(|(_, half)| *half).collect();
        // Median-cut regions over dark parts of a map are huge (and their sigmas with them)
        // but carry little light: no light is blurred wider than the widest among those that
        // carry at least the mean energy.
        let mean_energy = lights.lights.iter().map(|l| l.energy).sum::<f32>() / n as f32;
        let rule: Vec<f32> =
            lights.lights.iter().map(|l| blur_sigma(l.solid_angle, radius, 1.0, s.blur_scale)).collect();
        let widest = lights
            .lights
            .iter()
            .zip(&rule)
            .filter(|(l, _)| l.energy >= mean_energy)
            .map(|(_, s)| *s)
            .fold(0.0, f32::max);
        let sigma_world: Vec<f32> = rule.iter().map(|s| s.min(widest)).collect();
        let single = n <= MAX_TILES;
        let max_dim = gpu.limits.max_texture_dimension_2d;
        let by_penumbra = single && s.sizes == TileSizes::ByPenumbra;
        let (sizes, origins, width, height) = if by_penumbra {
            // Texels enough to resolve each penumbra (TEXELS_PER_SIGMA across its sigma) plus
            // its guard, scaled to the memory of n uniform tiles of tile_size.
            // Wants are taken across the scene's sphere, not the view-fitted extent, so the
            // layout (and the textures) stay the same while the camera moves.
            let wants: Vec<f32> = sigma_world
                .iter()
                .map(|sigma| 2.0 * radius * TEXELS_PER_SIGMA / sigma + 6.0 * TEXELS_PER_SIGMA)
                .collect();
            // No tile below half of tile_size: the blur rule takes a median-cut region's
            // whole solid angle for its light's extent, which is far too wide for a region
            // whose light comes from a small bright part, and an occluder must stay several
            // texels wide in every tile.
            allocate_and_pack(&wants, n as u64 * t as u64 * t as u64, t / 2, max_dim.min(1024))
        } else if single {
            let (origins, width, height) = pack_tiles(&vec![t; n]);
            (vec![t; n], origins, width, height)
        } else {
            let (columns, rows) = grid(n);
            let origins = (0..n as u32).map(|i| [(i % columns) * t, (i / columns) * t]).collect();
            (vec![t; n], origins, columns * t, rows * t)
        };
        // Uniform tiles share one guard, for the widest blur; tiles sized by penumbra have
        // their own. Either is at most an eighth of the tile.
        let uniform_guard =
            halves.iter().zip(&sigma_world).map(|(half, sigma)| sigma * t as f32 / (2.0 * half)).fold(0.0, f32::max);
        let guards: Vec<u32> = sizes
            .iter()
            .zip(halves.iter().zip(&sigma_world))
            .map(|(&size, (half, sigma))| match s.guard {
                Some(g) => g.min(size / 4),
                None if by_penumbra => ((3.0 * sigma * size as f32 / (2.0 * half)).ceil() as u32).min(size / 8),
                None => ((3.0 * uniform_guard).ceil() as u32).min(size / 8),
            })
            .collect();
        anyhow::ensure!(
            width <= max_dim && height <= max_dim,
            "a {width}x{height} atlas ({n} tiles of {t}) exceeds the device's {max_dim} texels"
        );
        let format = moments_format(gpu);
        let mut shadow_lights: Vec<ShadowLight> = (0..n)
            .map(|i| {
                let (l, size, guard) = (&lights.lights[i], sizes[i], guards[i]);
                let rect = [origins[i][0], origins[i][1], size, size];
                let view_proj = tile_view_proj(l.direction, center, radius, squares[i], size, guard);
                let texel_world = 2.0 * halves[i] / (size - 2 * guard) as f32;
                let sigma = (sigma_world[i] / texel_world).min(guard as f32 / 3.0);
                ShadowLight {
                    direction: l.direction.normalize_or(Vec3::Y),
                    view_proj,
                    to_atlas: clip_to_atlas(rect, width, height) * view_proj,
                    rect,
                    sigma,
                    texel_world,
                    normal_offset: 0.0,
                }
            })
            .collect();
        // The lookup offset is the finest tile's texels for every light: a coarse tile's
        // texel can be as large as the gap between an occluder and its receiver (the
        // blurred moments of a plane are symmetric about it, so coarse tiles need no more).
        let finest = shadow_lights.iter().map(|l| l.texel_world).fold(f32::MAX, f32::min);
        for l in &mut shadow_lights {
            l.normal_offset = params.normal_offset * finest;
        }

        let make_atlas = |gpu: &GpuContext| {
            let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_DST;
            let atlas = gpu.acquire("shadow atlas", TextureDesc::d2(width, height, format, usage));
            // Grid slots past the last light hold no tile: cleared (zeros) for inspection.
            gpu.record(|enc| {
                enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("shadow atlas clear"),
                    color_attachments: &[atlas.clear_attachment()],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
            });
            atlas
        };
        let mut atlas: Option<GpuImage> = None;
        for batch in shadow_lights.chunks(MAX_TILES) {
            // One batch is drawn in place; batches of many lights (uniform tiles of t) into a
            // texture 8 tiles wide, whose tiles are then copied into the atlas.
            let (bw, bh, rects): (u32, u32, Vec<[u32; 4]>) = if single {
                (width, height, batch.iter().map(|l| l.rect).collect())
            } else {
                let rects = (0..batch.len() as u32).map(|j| [(j % 8) * t, (j / 8) * t, t, t]).collect();
                (8 * t, (batch.len() as u32).div_ceil(8) * t, rects)
            };
            let tiles: Vec<Tile> =
                batch.iter().zip(&rects).map(|(l, rect)| Tile { view_proj: l.view_proj, rect: *rect }).collect();
            let depth = self.drawer.depth_tiles(gpu, items, &tiles, bw, bh)?;
            let moments = GpuImage::target(gpu, "vsm moments", bw, bh, format);
            let depth_as_float = Bind::View(
                &depth.view,
                wgpu::TextureViewDimension::D2,
                wgpu::TextureSampleType::Float { filterable: false },
            );
            self.moments.draw(gpu, &[Bind::Uniform(&[0u8; 16]), depth_as_float], &[&moments.view], &[format])?;
            let blur_tiles: Vec<([u32; 4], f32)> = rects.iter().zip(batch).map(|(r, l)| (*r, l.sigma)).collect();
            let blurred = self.blur(gpu, &moments, &blur_tiles)?;
            if single {
                atlas = Some(blurred);
            } else {
                let atlas = atlas.get_or_insert_with(|| make_atlas(gpu));
                gpu.record(|enc| {
                    for (rect, l) in rects.iter().zip(batch) {
                        enc.copy_texture_to_texture(
                            wgpu::TexelCopyTextureInfo {
                                texture: &blurred.texture,
                                mip_level: 0,
                                origin: wgpu::Origin3d { x: rect[0], y: rect[1], z: 0 },
                                aspect: wgpu::TextureAspect::All,
                            },
                            wgpu::TexelCopyTextureInfo {
                                texture: &atlas.texture,
                                mip_level: 0,
                                origin: wgpu::Origin3d { x: l.rect[0], y: l.rect[1], z: 0 },
                                aspect: wgpu::TextureAspect::All,
                            },
                            wgpu::Extent3d { width: t, height: t, depth_or_array_layers: 1 },
                        );
                    }
                });
            }
        }
        let atlas = atlas.expect("at least one batch");
        let bytes = width as u64 * height as u64 * format.block_copy_size(None).unwrap_or(4) as u64;
        Ok(ShadowAtlas {
            atlas,
            texel_world: shadow_lights.iter().map(|l| l.texel_world).fold(0.0, f32::max),
            guard: guards.iter().copied().max().unwrap_or(0),
            lights: shadow_lights,
            tile_size: t,
            center,
            radius,
            params,
            bytes,
        })
    }
}

#[derive(Default)]
struct ShadowAtlasNode {
    builder: AtlasBuilder,
}

impl Node for ShadowAtlasNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let scene: Arc<Vec<DrawItem>> = cx.input("scene")?;
        let lights: Arc<Lights> = cx.input("lights")?;
        let detail: usize = scene.iter().filter(|i| i.detail).map(|i| i.kind.drawn_triangles(i)).sum();
        let budget = cx.int("detail_triangle_budget").max(0) as usize;
        let coarse_only = cx.bool("coarse_only") || detail > budget;
        if coarse_only && !cx.bool("coarse_only") {
            cx.warn(format!(
                "the attachments' {detail} triangles are over detail_triangle_budget ({budget}): only coarse items cast shadows"
            ));
        }
        cx.count("detail_triangles", if coarse_only { 0 } else { detail });
        let items: Vec<DrawItem> = scene.iter().filter(|i| !(coarse_only && i.detail)).cloned().collect();
        let guard = cx.int("guard");
        let settings = AtlasSettings {
            tile_size: cx.int("tile_size").clamp(16, 1024) as u32,
            guard: (guard >= 0).then_some(guard as u32),
            coarse_only,
            blur_scale: cx.f32("blur_scale"),
            sizes: cx.choice("sizes"),
            fit_view: match cx.optional::<Camera>("camera") {
                Some(camera) if cx.bool("fit_to_view") => {
                    let (w, h) = cx.frame_size();
                    Some(View::new(&camera, w, h).inv_view_proj)
                }
                _ => None,
            },
        };
        let params = VsmParams {
            min_variance: cx.f32("min_variance"),
            bleed_reduction: cx.f32("bleed_reduction").clamp(0.0, 0.99),
            jitter: cx.f32("jitter"),
            normal_offset: cx.f32("normal_offset"),
            depth_bias: cx.f32("depth_bias"),
        };
        let atlas =
            self.builder.build(gpu, &items, &lights, &settings, params).map_err(|e| NodeError::msg(e.to_string()))?;
        cx.set("memory_mb", atlas.bytes as f64 / (1u64 << 20) as f64);
        cx.set("atlas", Arc::new(atlas.atlas.share()));
        cx.set("shadows", Arc::new(atlas));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_light_maps_the_bounding_sphere_into_the_inner_tile() {
        let (c, r, t, g) = (Vec3::new(1.0, 2.0, 3.0), 2.0, 128u32, 8u32);
        for dir in [Vec3::Y, Vec3::new(0.3, 0.8, -0.5).normalize(), -Vec3::Y, Vec3::X] {
            let vp = light_view_proj(dir, c, r, t, g);
            let inner = (t - 2 * g) as f32 / t as f32;
            // The sphere's extreme points across the view land on the inner square's edges.
            let up = if dir.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
            let side = dir.cross(up).normalize();
            let p = vp.project_point3(c + side * r);
            assert!((p.x.abs() - inner).abs() < 1e-4 && p.y.abs() < 1e-4, "{dir}: {p}");
            // Depth 0 toward the light, 1 away from it, linear.
            assert!(vp.project_point3(c + dir * r).z.abs() < 1e-5);
            assert!((vp.project_point3(c - dir * r).z - 1.0).abs() < 1e-5);
            assert!((vp.project_point3(c).z - 0.5).abs() < 1e-5);
        }
        // The atlas map puts the tile's centre at its rectangle's centre.
        let m = clip_to_atlas([128, 256, 128, 128], 512, 384);
        let centre = m.project_point3(Vec3::ZERO);
        assert!((centre.x - 192.0 / 512.0).abs() < 1e-6 && (centre.y - 320.0 / 384.0).abs() < 1e-6);
        let top_left = m.project_point3(Vec3::new(-1.0, 1.0, 0.0));
        assert!((top_left.x - 0.25).abs() < 1e-6 && (top_left.y - 256.0 / 384.0).abs() < 1e-6);
    }

    #[test]
    fn the_blur_rule_follows_the_solid_angle() {
        // A hemisphere is a cone of 90 degrees; a tiny region a tiny one.
        assert!((cone_angle(2.0 * std::f32::consts::PI) - std::f32::consts::FRAC_PI_2).abs() < 1e-5);
        assert!(cone_angle(1e-6) < 1e-2);
        // Omega = 4 pi / 128: theta ~ 10.1 degrees, tan ~ 0.178; R = 2, texel = 4/112.
        let s = blur_sigma(4.0 * std::f32::consts::PI / 128.0, 2.0, 4.0 / 112.0, 1.0);
        assert!((s - 0.178 * 0.5 * 28.0).abs() < 0.1, "{s}");
        assert_eq!(grid(1), (1, 1));
        assert_eq!(grid(5), (3, 2));
        assert_eq!(grid(128), (12, 11));
        assert_eq!(grid(512), (23, 23));
    }
}
