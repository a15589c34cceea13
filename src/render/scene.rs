//! Scene data that flows between render nodes: cameras, materials, drawable items, G-buffers.

use std::sync::{Arc, OnceLock};

use glam::{Mat4, Vec3};

use crate::gpu::{GpuContext, GpuImage};
use crate::mesh::Mesh;
use crate::render::draw::kind::ItemKind;
use crate::render::draw::kinds::mesh::PlainMesh;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    pub fov_y_degrees: f32,
    pub near: f32,
    pub far: f32,
}

impl Camera {
    pub fn view(&self) -> Mat4 {
        Mat4::look_at_rh(self.eye, self.target, self.up)
    }
    /// A right-handed perspective projection with depth in [0, 1] (wgpu's convention).
    pub fn projection(&self, aspect: f32) -> Mat4 {
        Mat4::perspective_rh(self.fov_y_degrees.to_radians(), aspect, self.near, self.far)
    }
}

/// A camera's matrices for one target size: made once per camera where the scene is drawn
/// (the G-buffer carries it) and shared by every screen-space pass, which reads positions back
/// from depth with `inv_view_proj` instead of rebuilding the projection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub view: Mat4,
    pub proj: Mat4,
    pub view_proj: Mat4,
    pub inv_view: Mat4,
    pub inv_proj: Mat4,
    pub inv_view_proj: Mat4,
    pub eye: Vec3,
    pub near: f32,
    pub far: f32,
    /// Target size in pixels.
    pub width: u32,
    pub height: u32,
    /// Sub-pixel offset of the projection in pixels (for temporal accumulation); zero here.
    pub jitter: glam::Vec2,
}

impl View {
    pub fn new(camera: &Camera, width: u32, height: u32) -> View {
        View::jittered(camera, width, height, glam::Vec2::ZERO)
    }

    /// A view whose projection is shifted by `jitter` pixels.
    pub fn jittered(camera: &Camera, width: u32, height: u32, jitter: glam::Vec2) -> View {
        let (w, h) = (width.max(1) as f32, height.max(1) as f32);
        let shift = Mat4::from_translation(Vec3::new(2.0 * jitter.x / w, -2.0 * jitter.y / h, 0.0));
        let view = camera.view();
        let proj = shift * camera.projection(w / h);
        let view_proj = proj * view;
        View {
            view,
            proj,
            view_proj,
            inv_view: view.inverse(),
            inv_proj: proj.inverse(),
            inv_view_proj: view_proj.inverse(),
            eye: camera.eye,
            near: camera.near,
            far: camera.far,
            width,
            height,
            jitter,
        }
    }
}

/// An RGBA8 (sRGB-encoded) image on the CPU, e.g. a material's base-colour map.
pub struct Image8 {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
    /// Colour (sRGB-encoded, decoded when sampled) or data such as a parameter map (as stored).
    pub srgb: bool,
    gpu: OnceLock<GpuImage>,
}

impl Image8 {
    /// A colour image, sRGB-encoded.
    pub fn new(width: u32, height: u32, rgba: Vec<u8>) -> Image8 {
        Image8 { width, height, rgba, srgb: true, gpu: OnceLock::new() }
    }

    /// A data image (a parameter map): shaders see the stored values.
    pub fn new_linear(width: u32, height: u32, rgba: Vec<u8>) -> Image8 {
        Image8 { width, height, rgba, srgb: false, gpu: OnceLock::new() }
    }

    /// Uploads on first use; colour images are sampled as sRGB so shaders see linear values.
    pub fn gpu(&self, gpu: &GpuContext) -> &GpuImage {
        self.gpu.get_or_init(|| {
            let format = if self.srgb { wgpu::TextureFormat::Rgba8UnormSrgb } else { wgpu::TextureFormat::Rgba8Unorm };
            GpuImage::upload(gpu, "image", self.width, self.height, format, 4, &self.rgba)
        })
    }
}

pub struct Material {
    /// Linear RGB.
    pub base_color: Vec3,
    /// 0 = rough, 1 = mirror-like; stored in the G-buffer's colour alpha.
    pub glossiness: f32,
    pub texture: Option<Arc<Image8>>,
    pub uv_scale: f32,
    /// A parameter map (dissertation Fig. 5.23): its red channel blends glossiness from
    /// `gloss_min` (0) to `glossiness` (1) within one material.
    pub gloss_map: Option<Arc<Image8>>,
    pub gloss_min: f32,
    /// Which `BtfShading` node shades this material: the one whose `material_id` equals it
    /// (written to the G-buffer's surface target); 0 for none.
    pub btf_id: u16,
}

/// What of a material a G-buffer pipeline compiles in (`MAPS` and `TANGENTS` in
/// shaders/common/gbuffer_common.wgsl). Lavapipe, the rasterizer without a GPU, runs both sides
/// of every branch, so maps a material lacks and a tangent frame no BTF reads are compiled out
/// rather than skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MaterialFeatures {
    /// A base or a gloss map is bound.
    pub maps: bool,
    /// A `BtfShading` node shades it (`btf_id` not 0): the surface target gets its tangent frame.
    pub tangents: bool,
}

impl Material {
    pub fn features(&self) -> MaterialFeatures {
        MaterialFeatures { maps: self.texture.is_some() || self.gloss_map.is_some(), tangents: self.btf_id != 0 }
    }
}

impl Default for Material {
    fn default() -> Self {
        Material {
            base_color: Vec3::splat(0.8),
            glossiness: 0.2,
            texture: None,
            uv_scale: 1.0,
            gloss_map: None,
            gloss_min: 0.0,
            btf_id: 0,
        }
    }
}

/// One mesh to draw, with its material, model transform and kind: how it is drawn and exported
/// (a plain mesh, attachments warped through a matrix texture, a GPU tessellation, per-pixel PN
/// depth; see `crate::render::draw::kind`).
#[derive(Clone)]
pub struct DrawItem {
    pub mesh: Arc<Mesh>,
    pub material: Arc<Material>,
    pub model: Mat4,
    /// Detail geometry (attachments) versus coarse cloth; written to the G-buffer flag.
    pub detail: bool,
    /// A non-linear (cuboid grid) transform applied after `model`: the vertex lands at
    /// `cuboid(model * p)` (dissertation section 3.1.1). None for the ordinary affine path.
    pub cuboid: Option<Arc<crate::cuboid::CuboidGrid>>,
    pub kind: Arc<dyn ItemKind>,
    /// Who made the item (the node's id, with a suffix where a node makes several), so an
    /// export can name its objects; None: exports name it by its kind.
    pub name: Option<Arc<str>>,
}

impl DrawItem {
    /// A coarse (non-detail) mesh drawn as it is.
    pub fn plain(mesh: Arc<Mesh>, material: Arc<Material>, model: Mat4) -> DrawItem {
        DrawItem { mesh, material, model, detail: false, cuboid: None, kind: Arc::new(PlainMesh), name: None }
    }

    /// This item named `name` (see [`DrawItem::name`]).
    pub fn named(self, name: impl Into<Arc<str>>) -> DrawItem {
        DrawItem { name: Some(name.into()), ..self }
    }

    /// This item drawn as `kind`.
    pub fn with_kind(self, kind: impl ItemKind) -> DrawItem {
        DrawItem { kind: Arc::new(kind), ..self }
    }

    /// Whether this coarse item draws `surface`: the same mesh, or one equal to it (an upstream
    /// node may hand the same vertices out twice).
    pub fn draws(&self, surface: &Arc<Mesh>) -> bool {
        !self.detail
            && (Arc::ptr_eq(&self.mesh, surface)
                || (self.mesh.positions.len() == surface.positions.len()
                    && self.mesh.indices == surface.indices
                    && self.mesh.positions == surface.positions))
    }
}

/// Whether two model transforms agree (to float noise).
pub fn same_transform(a: Mat4, b: Mat4) -> bool {
    a.abs_diff_eq(b, 1e-5 * (1.0 + a.abs().to_cols_array().into_iter().fold(0.0, f32::max)))
}

/// A model transform as its scale, rotation (XYZ degrees) and translation, for messages.
pub fn describe_transform(m: Mat4) -> String {
    let (scale, rotation, translation) = m.to_scale_rotation_translation();
    let (x, y, z) = rotation.to_euler(glam::EulerRot::XYZ);
    let round =
        |v: Vec3| format!("[{}, {}, {}]", round_for_message(v.x), round_for_message(v.y), round_for_message(v.z));
    format!(
        "translate {}, rotate {}, scale {}",
        round(translation),
        round(Vec3::new(x, y, z) * (180.0 / std::f32::consts::PI)),
        round(scale)
    )
}

/// A number as a message shows it: 4 significant digits, no trailing zeros, no "-0".
fn round_for_message(x: f32) -> String {
    let s = format!("{:.4}", x);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// The deferred renderer's multiple render targets.
pub struct GBuffer {
    /// Linear base colour (rgb) and glossiness (a), Rgba16Float.
    pub color: GpuImage,
    /// World-space normal (rgb) and the detail flag (a: 0 coarse, 1 detail), Rgba16Float.
    pub normal: GpuImage,
    /// Linear view-space depth, R32Float; 0 where nothing was drawn.
    pub depth: GpuImage,
    /// The surface (Rgba32Uint; shaders/common/surface.wgsl): UV, the tangent of increasing u
    /// (octahedral), the material's BTF id and the frame's handedness. 0 where nothing was drawn.
    pub surface: GpuImage,
    /// The hardware depth buffer, Depth32Float.
    pub depth_buffer: GpuImage,
    pub camera: Camera,
    /// The view the G-buffer was drawn with, for every pass that reads it.
    pub view: View,
}

impl GBuffer {
    pub fn width(&self) -> u32 {
        self.color.width
    }
    pub fn height(&self) -> u32 {
        self.color.height
    }
}

/// The corners of the box (lo, hi), corner k at (x, y, z) = (k & 1, k & 2, k & 4) of the unit cube.
pub fn box_corners(lo: Vec3, hi: Vec3) -> [Vec3; 8] {
    std::array::from_fn(|k| {
        Vec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        )
    })
}

/// The box (lo, hi) around the items' transformed mesh bounds (model matrix applied to their
/// box corners); None without geometry.
pub fn scene_box<'a>(items: impl IntoIterator<Item = &'a DrawItem>) -> Option<(Vec3, Vec3)> {
    let mut bounds: Option<(Vec3, Vec3)> = None;
    for item in items {
        let (lo, hi) = item.mesh.bounds();
        if lo.x > hi.x {
            continue;
        }
        for corner in box_corners(lo, hi) {
            let p = item.model.transform_point3(corner);
            bounds = Some(bounds.map_or((p, p), |(a, b)| (a.min(p), b.max(p))));
        }
    }
    bounds
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_view_inverts_its_own_matrices_and_jitter_shifts_by_pixels() {
        let camera = Camera {
            eye: Vec3::new(1.0, 2.0, 3.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_degrees: 45.0,
            near: 0.1,
            far: 50.0,
        };
        let v = View::new(&camera, 64, 32);
        assert!((v.view_proj * v.inv_view_proj).abs_diff_eq(Mat4::IDENTITY, 1e-4));
        assert!(v.inv_view.transform_point3(Vec3::ZERO).abs_diff_eq(camera.eye, 1e-5));
        // The target lands in the centre; a one-pixel jitter moves it by 2/width in NDC.
        let centre = v.view_proj.project_point3(Vec3::ZERO);
        assert!(centre.truncate().abs_diff_eq(glam::Vec2::ZERO, 1e-5));
        let shifted = View::jittered(&camera, 64, 32, glam::Vec2::new(1.0, 0.0)).view_proj.project_point3(Vec3::ZERO);
        assert!((shifted.x - 2.0 / 64.0).abs() < 1e-5 && shifted.y.abs() < 1e-5);
    }
}
