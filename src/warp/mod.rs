//! Deferred warping data (Knuth et al., "Deferred Warping"): the matrix texture, placements,
//! curves, per-instance transforms, and a CPU reference of the warp used by the CPU
//! benchmark path and by tests to cross-check the GPU.

pub mod gpu;
pub mod landmarks;

use std::sync::Arc;

use glam::{Mat3, Mat4, Vec2, Vec3, Vec4};

use crate::gpu::GpuImage;
use crate::mesh::Mesh;

/// The matrix texture: per texel the 3x4 matrix [t_u n t_v p] of eq. (3), as three RGBA
/// textures holding one column each plus one position component in w.
pub struct MatrixTexture {
    pub col_u: GpuImage,
    pub col_n: GpuImage,
    pub col_v: GpuImage,
    /// The seam map (see `seam_map`), Rgba32Float; all zero for a surface without seams.
    pub seams: GpuImage,
    pub resolution: u32,
    /// The surface as linked (before its transform) and the model transform the texture was
    /// rendered with, so a scene can check that the surface is drawn with the same one.
    pub placed_on: Option<(Arc<Mesh>, Mat4)>,
}

impl MatrixTexture {
    /// Whether the surface has sewn seams (a surface without binds a 1x1 placeholder map).
    pub fn has_seams(&self) -> bool {
        self.seams.width > 1
    }
}

/// A frame read back from the matrix texture (for tests and CPU paths).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelFrame {
    pub tu: Vec3,
    pub n: Vec3,
    pub tv: Vec3,
    pub p: Vec3,
}

/// A matrix texture copied to the CPU.
pub struct MatrixTexels {
    pub resolution: u32,
    pub frames: Vec<TexelFrame>,
    pub seams: Vec<[f32; 4]>,
}

impl MatrixTexels {
    pub fn at(&self, x: u32, y: u32) -> TexelFrame {
        self.frames[(y * self.resolution + x) as usize]
    }

    pub fn is_empty_texel(&self, x: u32, y: u32) -> bool {
        self.at(x, y).n.length_squared() < 0.25
    }

    fn covered(&self, x: i32, y: i32) -> Option<TexelFrame> {
        let res = self.resolution as i32;
        if x < 0 || y < 0 || x >= res || y >= res {
            return None;
        }
        let t = self.at(x as u32, y as u32);
        (t.n.length_squared() >= 0.25).then_some(t)
    }

    /// The frame a footprint texel contributes: its own if a piece covers it, else, for a gutter
    /// texel beside a seam, the partner piece's frame (bilinear over its covered texels) turned
    /// into this piece's UV directions. The CPU twin of `texel_or_partner` in shaders/warp/warp.wgsl.
    fn texel_or_partner(&self, x: i32, y: i32) -> Option<TexelFrame> {
        let res = self.resolution as i32;
        if let Some(t) = self.covered(x, y) {
            return Some(t);
        }
        let &[pu, pv, angle, sigma] = self.seams.get((y * res + x) as usize)?;
        if sigma == 0.0 {
            return None;
        }
        let b = self.partner_bilinear(Vec2::new(pu, pv))?;
        let m = seam_rotation(angle, sigma);
        Some(TexelFrame { tu: b.tu * m[0][0] + b.tv * m[0][1], n: b.n, tv: b.tu * m[1][0] + b.tv * m[1][1], p: b.p })
    }

    /// The CPU twin of `partner_bilinear` in shaders/warp/warp.wgsl.
    fn partner_bilinear(&self, uv: Vec2) -> Option<TexelFrame> {
        let (base, f) = footprint(uv, self.resolution);
        let (mut acc, mut weight) = (TexelFrame { tu: Vec3::ZERO, n: Vec3::ZERO, tv: Vec3::ZERO, p: Vec3::ZERO }, 0.0);
        for k in 0..4 {
            let (ox, oy) = (k & 1, k >> 1);
            let Some(t) = self.covered(base.0 + ox, base.1 + oy) else { continue };
            let w = bilinear_weight(f, ox, oy);
            acc.tu += w * t.tu;
            acc.n += w * t.n;
            acc.tv += w * t.tv;
            acc.p += w * t.p;
            weight += w;
        }
        (weight > 0.0).then(|| TexelFrame {
            tu: acc.tu / weight,
            n: acc.n / weight,
            tv: acc.tv / weight,
            p: acc.p / weight,
        })
    }

    /// The CPU twin of `lookup_frame` in shaders/warp/warp.wgsl.
    pub fn lookup(&self, uv: Vec2, min_weight: f32) -> Option<TexelFrame> {
        self.lookup_surface(uv, min_weight).map(|s| s.frame)
    }

    /// `lookup` with the derivatives dp/du, dp/dv of the interpolated position field.
    pub fn lookup_surface(&self, uv: Vec2, min_weight: f32) -> Option<SurfaceFrame> {
        let res = self.resolution as i32;
        let (base, f) = footprint(uv, self.resolution);
        let (mut su, mut sn, mut sv, mut sp, mut weight) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, 0.0);
        let mut ps = [None; 4];
        for (k, slot) in ps.iter_mut().enumerate() {
            let (ox, oy) = ((k & 1) as i32, (k >> 1) as i32);
            let (qx, qy) = (base.0 + ox, base.1 + oy);
            if qx < 0 || qy < 0 || qx >= res || qy >= res {
                continue;
            }
            let Some(t) = self.texel_or_partner(qx, qy) else { continue };
            *slot = Some(t.p);
            let w = bilinear_weight(f, ox, oy);
            su += w * t.tu;
            sn += w * t.n;
            sv += w * t.tv;
            sp += w * t.p;
            weight += w;
        }
        // Written as the shader's positive tests, so NaN is an outlier on both.
        if weight.is_nan() || weight < min_weight.max(1e-6) {
            return None;
        }
        let (u, n, v) = (su / weight, sn / weight, sv / weight);
        let unit = |x: f32| (x - 1.0).abs() < 0.25;
        if !(unit(n.length()) && unit(u.length())) {
            return None;
        }
        let n = n.normalize();
        let tu = (u - n * n.dot(u)).normalize();
        let tv = (v - n * n.dot(v) - tu * tu.dot(v)).normalize();
        let (mut du, mut dv, mut wu, mut wv) = (Vec3::ZERO, Vec3::ZERO, 0.0, 0.0);
        let pair = |a: usize, b: usize, w: f32, d: &mut Vec3, ws: &mut f32| {
            if let (Some(pa), Some(pb)) = (ps[a], ps[b]) {
                *d += w * (pb - pa);
                *ws += w;
            }
        };
        pair(0, 1, 1.0 - f.y, &mut du, &mut wu);
        pair(2, 3, f.y, &mut du, &mut wu);
        pair(0, 2, 1.0 - f.x, &mut dv, &mut wv);
        pair(1, 3, f.x, &mut dv, &mut wv);
        let frame = TexelFrame { tu, n, tv, p: sp / weight };
        let [dpdu, dpdv] = uv_derivatives(du, wu, dv, wv, Vec2::splat(self.resolution as f32), &frame);
        Some(SurfaceFrame { frame, dpdu, dpdv })
    }
}

/// A looked-up surface frame with the derivatives of the interpolated position field: world
/// units per UV unit, the local UV-to-world scale and shear of area and curve attachments.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceFrame {
    pub frame: TexelFrame,
    pub dpdu: Vec3,
    pub dpdv: Vec3,
}

/// The texel at the footprint's top-left and the fractional position in it (bilinear lookup).
fn footprint(uv: Vec2, resolution: u32) -> ((i32, i32), Vec2) {
    let st = uv * resolution as f32 - Vec2::splat(0.5);
    let base = st.floor();
    ((base.x as i32, base.y as i32), st - base)
}

fn bilinear_weight(f: Vec2, ox: i32, oy: i32) -> f32 {
    (if ox == 1 { f.x } else { 1.0 - f.x }) * if oy == 1 { f.y } else { 1.0 - f.y }
}

/// The CPU twin of `uv_derivatives` in shaders/warp/warp.wgsl.
fn uv_derivatives(du: Vec3, wu: f32, dv: Vec3, wv: f32, dims: Vec2, f: &TexelFrame) -> [Vec3; 2] {
    let a = if wu > 1e-6 { du * (dims.x / wu) } else { f.tu };
    let b = if wv > 1e-6 { dv * (dims.y / wv) } else { f.tv };
    let (mut a, mut b) = (a - f.n * f.n.dot(a), b - f.n * f.n.dot(b));
    if wu <= 1e-6 && wv > 1e-6 {
        a = f.tu * b.length();
    }
    if wv <= 1e-6 && wu > 1e-6 {
        b = f.tv * a.length();
    }
    [a, b]
}

/// The 2x2 map from this piece's UV directions to the partner's, as rows of coefficients:
/// this piece's u axis is `m[0][0] t_u' + m[0][1] t_v'` of the partner. `sigma` is +1 for a
/// rotation, -1 for a rotation with a reflection.
pub fn seam_rotation(angle: f32, sigma: f32) -> [[f32; 2]; 2] {
    let (s, c) = angle.sin_cos();
    // Columns of M (A's u and v directions expressed in B's UV), transposed into rows.
    if sigma > 0.0 { [[c, s], [-s, c]] } else { [[c, s], [s, -c]] }
}

/// The seam map of a surface at `res` x `res`: for texels within `gutter` texels outside a
/// piece's boundary edge that is sewn to another piece, the UV of the corresponding point
/// inside the partner piece (as far inside as the texel is outside), and the rotation (and
/// reflection) from this piece's UV directions to the partner's. Lookups that reach past a
/// seam then blend both pieces' frames (dissertation section 4.1.2, "Outliers and Seams").
/// Texels elsewhere are zero.
pub fn seam_map(mesh: &Mesh, res: u32, gutter: f32) -> Vec<[f32; 4]> {
    use std::collections::HashMap;
    let mut map = vec![[0.0f32; 4]; (res * res) as usize];
    if mesh.seams.is_empty() {
        return map;
    }
    // Boundary edges (used by one triangle) with the opposite vertex, to know which side is inside.
    let mut edges: HashMap<(u32, u32), (u32, u32)> = HashMap::new();
    for t in mesh.indices.chunks_exact(3) {
        for (a, b, c) in [(t[0], t[1], t[2]), (t[1], t[2], t[0]), (t[2], t[0], t[1])] {
            edges.entry((a.min(b), a.max(b))).and_modify(|e| e.1 += 1).or_insert((c, 1));
        }
    }
    let boundary: HashMap<(u32, u32), u32> =
        edges.into_iter().filter(|(_, (_, n))| *n == 1).map(|(k, (opp, _))| (k, opp)).collect();
    let mut partners: HashMap<u32, Vec<u32>> = HashMap::new();
    for &[a, b] in &mesh.seams {
        partners.entry(a).or_default().push(b);
        partners.entry(b).or_default().push(a);
    }
    let uv = |i: u32| mesh.uvs[i as usize];
    let mut best = vec![f32::MAX; map.len()];
    let texel = 1.0 / res as f32;
    let reach = gutter * texel;
    let mut sorted: Vec<(&(u32, u32), &u32)> = boundary.iter().collect();
    sorted.sort();
    for (&(a0, a1), &opp_a) in sorted {
        let (Some(p0), Some(p1)) = (partners.get(&a0), partners.get(&a1)) else { continue };
        // The partner edge: a boundary edge between partners of both ends.
        let Some((b0, b1, opp_b)) = p0.iter().find_map(|&b0| {
            p1.iter().find_map(|&b1| boundary.get(&(b0.min(b1), b0.max(b1))).map(|&opp| (b0, b1, opp)))
        }) else {
            continue;
        };
        let (ua0, ua1, ub0, ub1) = (uv(a0), uv(a1), uv(b0), uv(b1));
        let (ea, eb) = (ua1 - ua0, ub1 - ub0);
        if ea.length_squared() < 1e-14 || eb.length_squared() < 1e-14 {
            continue;
        }
        let (ea_hat, eb_hat) = (ea.normalize(), eb.normalize());
        let inward = |e: Vec2, o: Vec2| {
            let n = e.perp();
            if n.dot(o) >= 0.0 { n } else { -n }
        };
        let out_a = -inward(ea_hat, uv(opp_a) - ua0);
        let in_b = inward(eb_hat, uv(opp_b) - ub0);
        // M maps A's UV directions to B's: e_A -> e_B, outward_A -> inward_B.
        let m00 = eb_hat.x * ea_hat.x + in_b.x * out_a.x;
        let m01 = eb_hat.x * ea_hat.y + in_b.x * out_a.y;
        let m10 = eb_hat.y * ea_hat.x + in_b.y * out_a.x;
        let m11 = eb_hat.y * ea_hat.y + in_b.y * out_a.y;
        let sigma = (m00 * m11 - m01 * m10).signum();
        let angle = m10.atan2(m00);
        let scale = eb.length() / ea.length();
        let lo = ua0.min(ua1) - Vec2::splat(reach);
        let hi = ua0.max(ua1) + Vec2::splat(reach);
        let cell = |x: f32| ((x * res as f32).floor() as i64).clamp(0, res as i64 - 1) as u32;
        for y in cell(lo.y)..=cell(hi.y) {
            for x in cell(lo.x)..=cell(hi.x) {
                let c = Vec2::new((x as f32 + 0.5) * texel, (y as f32 + 0.5) * texel);
                let rel = c - ua0;
                let t = (rel.dot(ea) / ea.length_squared()).clamp(0.0, 1.0);
                let d = rel.dot(out_a);
                let dist = (rel - ea * t).length();
                if d <= 0.0 || dist > reach {
                    continue;
                }
                let i = (y * res + x) as usize;
                if dist < best[i] {
                    best[i] = dist;
                    let pb = ub0 + eb * t + in_b * (d * scale);
                    map[i] = [pb.x, pb.y, angle, sigma];
                }
            }
        }
    }
    map
}

/// How detail geometry is attached (paper sections 3.3-3.5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WarpMode {
    Point = 0,
    Area = 1,
    Curve = 2,
    CurveAligned = 3,
    /// No matrix texture lookup: M_tex's translation is the xz offset. The baseline of
    /// `werkstatt bench attachments` (plain instancing of the same geometry).
    Unattached = 4,
}

/// One placement of detail geometry in texture space (a designer's layout row).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    pub piece: u32,
    pub u: f32,
    pub v: f32,
    /// Rotation about the surface normal, degrees.
    pub angle: f32,
    pub scale: f32,
}

/// Cubic Bezier segments in UV space (control points p0..p3), grouped into paths.
#[derive(Clone, Debug, Default)]
pub struct Curves {
    pub paths: Vec<Vec<[Vec2; 4]>>,
}

impl Curves {
    pub fn segment_count(&self) -> usize {
        self.paths.iter().map(Vec::len).sum()
    }
}

pub fn bezier(c: &[Vec2; 4], t: f32) -> Vec2 {
    let s = 1.0 - t;
    c[0] * (s * s * s) + c[1] * (3.0 * s * s * t) + c[2] * (3.0 * s * t * t) + c[3] * (t * t * t)
}

pub fn bezier_tangent(c: &[Vec2; 4], t: f32) -> Vec2 {
    let s = 1.0 - t;
    (c[1] - c[0]) * (3.0 * s * s) + (c[2] - c[1]) * (6.0 * s * t) + (c[3] - c[2]) * (3.0 * t * t)
}

/// Arc length along a path, sampled: (segment, t, cumulative length) per sample.
pub struct ArcTable {
    samples: Vec<(usize, f32, f32)>,
}

impl ArcTable {
    pub fn new(path: &[[Vec2; 4]], per_segment: usize) -> ArcTable {
        let mut samples = vec![(0, 0.0, 0.0)];
        let mut total = 0.0;
        for (i, seg) in path.iter().enumerate() {
            let mut prev = bezier(seg, 0.0);
            for k in 1..=per_segment {
                let t = k as f32 / per_segment as f32;
                let p = bezier(seg, t);
                total += (p - prev).length();
                prev = p;
                samples.push((i, t, total));
            }
        }
        ArcTable { samples }
    }

    pub fn length(&self) -> f32 {
        self.samples.last().map_or(0.0, |s| s.2)
    }

    /// The (segment, t) at arc length `s`, interpolating between samples.
    pub fn at(&self, s: f32) -> (usize, f32) {
        let i = self.samples.partition_point(|x| x.2 < s).clamp(1, self.samples.len().max(2) - 1);
        let (a, b) = (self.samples[i - 1], self.samples[i]);
        if a.0 != b.0 {
            return (b.0, (b.1 * (s - a.2) / (b.2 - a.2).max(1e-12)).clamp(0.0, 1.0));
        }
        let w = ((s - a.2) / (b.2 - a.2).max(1e-12)).clamp(0.0, 1.0);
        (a.0, a.1 + (b.1 - a.1) * w)
    }
}

/// Per-instance data, laid out as the `Instance` struct of shaders/warp/warp.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct InstanceData {
    /// Rows of M_tex (2x3): u' = dot(row0.xyz, (u, v, 1)).
    pub m_tex0: [f32; 4],
    pub m_tex1: [f32; 4],
    /// Columns of M_tan.
    pub m_tan: [[f32; 4]; 4],
    pub curve01: [f32; 4],
    pub curve23: [f32; 4],
    /// t0, t1, z0, z1.
    pub range: [f32; 4],
}

impl InstanceData {
    pub const ATTRIBUTES: [wgpu::VertexAttribute; 9] = wgpu::vertex_attr_array![
        5 => Float32x4, 6 => Float32x4, 7 => Float32x4, 8 => Float32x4, 9 => Float32x4,
        10 => Float32x4, 11 => Float32x4, 12 => Float32x4, 13 => Float32x4
    ];

    pub fn layout() -> wgpu::VertexBufferLayout<'static> {
        wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<InstanceData>() as u64,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &Self::ATTRIBUTES,
        }
    }

    /// M_tex as an affine map of UV space: scale, rotation (degrees) and translation.
    pub fn with_tex(mut self, m: glam::Affine2) -> Self {
        let (c0, c1, t) = (m.matrix2.x_axis, m.matrix2.y_axis, m.translation);
        self.m_tex0 = [c0.x, c1.x, t.x, 0.0];
        self.m_tex1 = [c0.y, c1.y, t.y, 0.0];
        self
    }

    pub fn with_tan(mut self, m: Mat4) -> Self {
        self.m_tan = m.to_cols_array_2d();
        self
    }

    pub fn with_curve(mut self, c: &[Vec2; 4], t0: f32, t1: f32, z0: f32, z1: f32) -> Self {
        self.curve01 = [c[0].x, c[0].y, c[1].x, c[1].y];
        self.curve23 = [c[2].x, c[2].y, c[3].x, c[3].y];
        self.range = [t0, t1, z0, z1];
        self
    }

    pub fn identity() -> Self {
        InstanceData::default().with_tex(glam::Affine2::IDENTITY).with_tan(Mat4::IDENTITY)
    }

    fn m_tan_matrix(&self) -> Mat4 {
        Mat4::from_cols_array_2d(&self.m_tan)
    }

    /// M_tan's linear part: the Jacobian of a point attachment (eq. 5).
    fn m_tan_linear(&self) -> Mat3 {
        let col = |i: usize| Vec4::from_array(self.m_tan[i]).truncate();
        Mat3::from_cols(col(0), col(1), col(2))
    }

    fn curve(&self) -> [Vec2; 4] {
        [
            Vec2::new(self.curve01[0], self.curve01[1]),
            Vec2::new(self.curve01[2], self.curve01[3]),
            Vec2::new(self.curve23[0], self.curve23[1]),
            Vec2::new(self.curve23[2], self.curve23[3]),
        ]
    }
}

/// Uniform settings of one attachment draw, laid out as `Warp` in shaders/warp/warp.wgsl.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WarpSettings {
    pub mode: WarpMode,
    /// Fur gravity c of eq. (11); 0 = off.
    pub gravity: f32,
    /// Lowest accepted sum of bilinear weights of valid texels; below it a vertex is an outlier.
    pub min_weight: f32,
}

/// `Warp` in shaders/warp/warp.wgsl, field for field.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct WarpUniform {
    /// Unused: the mode is the pipeline's constant `MODE` ([`WarpSettings::constants`]).
    pub unused: f32,
    /// Fur gravity c of eq. (11).
    pub gravity: f32,
    /// Lowest valid-texel weight.
    pub min_weight: f32,
    pub _pad: f32,
}

impl WarpSettings {
    /// The `Warp` uniform; `resolved`: point frames were looked up per instance (mode 5).
    pub fn uniform(&self) -> WarpUniform {
        WarpUniform { unused: 0.0, gravity: self.gravity, min_weight: self.min_weight, _pad: 0.0 }
    }

    /// The override constants of shaders/warp/warp.wgsl: `MODE` (0 point, 1 area, 2 curve, 3
    /// curve aligned to the curve normal, 4 no surface (plain instancing, a benchmark baseline),
    /// 5 point with the frame resolved once per instance; `resolved`: point frames were looked up
    /// per instance) and `GRAVITY`.
    pub fn constants(&self, resolved: bool) -> [(&'static str, u32); 2] {
        let mode = if resolved && self.mode == WarpMode::Point { 5 } else { self.mode as u32 };
        [("MODE", mode), ("GRAVITY", u32::from(self.gravity > 0.0))]
    }
}

/// Attached detail geometry as drawn by the G-buffer pass.
pub struct AttachedDraw {
    pub matrix: Arc<MatrixTexture>,
    pub settings: WarpSettings,
    pub instances: Arc<Vec<InstanceData>>,
    instance_buffer: std::sync::OnceLock<crate::gpu::PooledBuffer>,
    resolved_buffer: std::sync::OnceLock<Result<crate::gpu::PooledBuffer, String>>,
}

impl AttachedDraw {
    pub fn new(matrix: Arc<MatrixTexture>, settings: WarpSettings, instances: Vec<InstanceData>) -> Self {
        AttachedDraw {
            matrix,
            settings,
            instances: Arc::new(instances),
            instance_buffer: Default::default(),
            resolved_buffer: Default::default(),
        }
    }

    pub fn instance_buffer(&self, gpu: &crate::gpu::GpuContext) -> &wgpu::Buffer {
        self.instance_buffer.get_or_init(|| {
            let bytes: &[u8] = if self.instances.is_empty() {
                &[0u8; std::mem::size_of::<InstanceData>()]
            } else {
                bytemuck::cast_slice(&self.instances)
            };
            gpu.upload_pooled(
                "attachment instances",
                bytes,
                wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            )
        })
    }
}

impl AttachedDraw {
    /// Whether this draw's frames are resolved once per instance (point attachments).
    pub fn per_instance_frames(&self) -> bool {
        self.settings.mode == WarpMode::Point
    }

    /// The instances to draw: for point attachments with their frames resolved by
    /// `resolve` (a compute pass, run once per draw and matrix texture), else as given.
    pub fn draw_buffer(
        &self,
        gpu: &crate::gpu::GpuContext,
        resolve: impl FnOnce(&wgpu::Buffer) -> anyhow::Result<crate::gpu::PooledBuffer>,
    ) -> anyhow::Result<&wgpu::Buffer> {
        let raw = self.instance_buffer(gpu);
        if !self.per_instance_frames() {
            return Ok(raw);
        }
        self.resolved_buffer
            .get_or_init(|| resolve(raw).map_err(|e| format!("{e:#}")))
            .as_ref()
            .map(|b| &**b)
            .map_err(|e| anyhow::anyhow!("{e}"))
    }
}

/// A warped vertex from the CPU reference.
#[derive(Clone, Copy, Debug)]
pub struct WarpedVertex {
    pub position: Vec3,
    pub normal: Vec3,
    pub valid: bool,
}

/// The CPU reference of `warp_vertex` in shaders/warp/warp.wgsl (eqs. 1-12).
pub fn warp_vertex_cpu(
    texels: &MatrixTexels,
    s: &WarpSettings,
    inst: &InstanceData,
    p: Vec3,
    normal: Vec3,
) -> WarpedVertex {
    let mut uv_in = Vec2::ZERO;
    let mut f_map = p.extend(1.0);
    let mut t = 0.0;
    let mut nc = Vec2::X;
    let c = inst.curve();
    match s.mode {
        WarpMode::Point | WarpMode::Unattached => {}
        WarpMode::Area => {
            uv_in = Vec2::new(p.x, p.z);
            f_map = Vec4::new(0.0, p.y, 0.0, 1.0);
        }
        WarpMode::Curve | WarpMode::CurveAligned => {
            let r = inst.range;
            let sz = (p.z - r[2]) / (r[3] - r[2]).max(1e-12);
            t = r[0] + (r[1] - r[0]) * sz;
            uv_in = bezier(&c, t);
            f_map = Vec4::new(p.x, p.y, 0.0, 1.0);
            if s.mode == WarpMode::CurveAligned {
                let d = curve_direction(&c, t);
                nc = Vec2::new(d.y, -d.x);
                f_map = Vec4::new(nc.x * p.x, p.y, nc.y * p.x, 1.0);
            }
        }
    }
    let Some(sf) = frame_at(texels, s, inst, uv_in) else {
        return OUTLIER;
    };
    let f = sf.frame;
    let q = (inst.m_tan_matrix() * f_map).truncate();
    let to_frame = |w: Vec3| Vec3::new(f.tu.dot(w), f.n.dot(w), f.tv.dot(w));
    let uv_to_frame = |d: Vec2| {
        let e = Vec2::new(inst.m_tex0[0] * d.x + inst.m_tex0[1] * d.y, inst.m_tex1[0] * d.x + inst.m_tex1[1] * d.y);
        to_frame(sf.dpdu * e.x + sf.dpdv * e.y)
    };
    let col = |i: usize| Vec4::from_array(inst.m_tan[i]).truncate();
    let jac = match s.mode {
        WarpMode::Area => Mat3::from_cols(uv_to_frame(Vec2::X), col(1), uv_to_frame(Vec2::Y)),
        WarpMode::Curve | WarpMode::CurveAligned => {
            let r = inst.range;
            let speed = bezier_tangent(&c, t).length().max(1e-6) * (r[1] - r[0]) / (r[3] - r[2]).max(1e-12);
            let along = uv_to_frame(curve_direction(&c, t) * speed);
            Mat3::from_cols(col(0) * nc.x + col(2) * nc.y, col(1), along)
        }
        WarpMode::Point | WarpMode::Unattached => inst.m_tan_linear(),
    };
    place_in_frame(&f, s.gravity, q, jac, normal)
}

const OUTLIER: WarpedVertex = WarpedVertex { position: Vec3::ZERO, normal: Vec3::Y, valid: false };

/// The surface frame at M_tex . f_uv (eq. 1), or None for an outlier.
fn frame_at(texels: &MatrixTexels, s: &WarpSettings, inst: &InstanceData, uv_in: Vec2) -> Option<SurfaceFrame> {
    let h = uv_in.extend(1.0);
    let uv = Vec2::new(Vec3::from_slice(&inst.m_tex0).dot(h), Vec3::from_slice(&inst.m_tex1).dot(h));
    if s.mode == WarpMode::Unattached {
        let frame = TexelFrame { tu: Vec3::X, n: Vec3::Y, tv: Vec3::Z, p: Vec3::new(uv.x, 0.0, uv.y) };
        return Some(SurfaceFrame { frame, dpdu: Vec3::X, dpdv: Vec3::Z });
    }
    texels.lookup_surface(uv, s.min_weight)
}

/// The last step of `warp_vertex_cpu`: fur gravity (eqs. 11-12) on the point `q` in frame
/// coordinates, then frame to world; the normal goes through the cofactor of `jac`.
fn place_in_frame(f: &TexelFrame, gravity: f32, mut q: Vec3, mut jac: Mat3, normal: Vec3) -> WarpedVertex {
    if gravity > 0.0 {
        let (bent, db) = fur_bend(f, q, gravity);
        q = bent;
        jac = Mat3::from_cols(Vec3::X, db, Vec3::Z) * jac;
    }
    frame_to_world(f, q, normal_matrix(jac) * normal)
}

fn frame_to_world(f: &TexelFrame, q: Vec3, nt: Vec3) -> WarpedVertex {
    let position = f.tu * q.x + f.n * q.y + f.tv * q.z + f.p;
    let normal = (f.tu * nt.x + f.n * nt.y + f.tv * nt.z).normalize();
    WarpedVertex { position, normal, valid: true }
}

/// `warp_vertex_cpu` for every vertex of one instance, into `put(vertex index, result)`. A
/// point attachment looks up one frame for all its vertices (eq. 4: f_uv is constant), and
/// without fur gravity one normal matrix, as attach_resolve.wgsl does on the GPU; the
/// arithmetic per vertex is the same, so results are bit-identical to `warp_vertex_cpu`.
pub fn warp_instance_cpu(
    texels: &MatrixTexels,
    s: &WarpSettings,
    inst: &InstanceData,
    mesh: &Mesh,
    mut put: impl FnMut(usize, WarpedVertex),
) {
    let vertices = mesh.positions.iter().enumerate().map(|(v, p)| (v, (p, &mesh.normals[v])));
    if !matches!(s.mode, WarpMode::Point | WarpMode::Unattached) {
        for (v, (&p, &n)) in vertices {
            put(v, warp_vertex_cpu(texels, s, inst, p, n));
        }
        return;
    }
    let Some(sf) = frame_at(texels, s, inst, Vec2::ZERO) else {
        (0..mesh.positions.len()).for_each(|v| put(v, OUTLIER));
        return;
    };
    let (m_tan, jac) = (inst.m_tan_matrix(), inst.m_tan_linear());
    let straight = (s.gravity <= 0.0).then(|| normal_matrix(jac));
    for (v, (&p, &n)) in vertices {
        let q = (m_tan * p.extend(1.0)).truncate();
        put(
            v,
            match straight {
                Some(nm) => frame_to_world(&sf.frame, q, nm * n),
                None => place_in_frame(&sf.frame, s.gravity, q, jac, n),
            },
        );
    }
}

/// Each instance's placement as one affine map of the detail mesh, where the warp is one
/// (a point attachment without fur gravity: one frame per instance, eqs. 4-5): the frame
/// [t_u n t_v | p] after M_tan, as `warp_instance_cpu` places every vertex. None for other
/// modes; an outlier instance (no frame) gets the zero matrix (it has no triangles).
pub fn rigid_placements(texels: &MatrixTexels, s: &WarpSettings, instances: &[InstanceData]) -> Option<Vec<Mat4>> {
    if !matches!(s.mode, WarpMode::Point | WarpMode::Unattached) || s.gravity > 0.0 {
        return None;
    }
    let place = |inst: &InstanceData| {
        frame_at(texels, s, inst, Vec2::ZERO).map_or(Mat4::ZERO, |sf| {
            let f = sf.frame;
            Mat4::from_cols(f.tu.extend(0.0), f.n.extend(0.0), f.tv.extend(0.0), f.p.extend(1.0)) * inst.m_tan_matrix()
        })
    };
    Some(instances.iter().map(place).collect())
}

/// The CPU twin of `fur_bend` in shaders/warp/warp.wgsl (eqs. 11-12 in frame coordinates): the
/// bent point and its derivative by the height.
pub fn fur_bend(f: &TexelFrame, q: Vec3, c: f32) -> (Vec3, Vec3) {
    let up = Vec3::new(f.tu.y, f.n.y, f.tv.y);
    let b = q.y;
    let w = Vec3::Y - c * b * up;
    let lw = w.length();
    if lw < 1e-10 {
        return (q, Vec3::Y);
    }
    let u = w / lw;
    let bent = Vec3::new(q.x, 0.0, q.z) + b * u;
    (bent, u - b * c * (up - u * u.dot(up)) / lw)
}

/// The CPU twin of `normal_matrix` in shaders/warp/warp.wgsl: cofactors with the determinant's sign.
pub fn normal_matrix(m: Mat3) -> Mat3 {
    let (c0, c1, c2) = (m.y_axis.cross(m.z_axis), m.z_axis.cross(m.x_axis), m.x_axis.cross(m.y_axis));
    let sign = if m.x_axis.dot(c0) < 0.0 { -1.0 } else { 1.0 };
    Mat3::from_cols(c0, c1, c2) * sign
}

/// The CPU twin of `curve_direction` in shaders/warp/warp.wgsl: the tangent's direction, or at a
/// degenerate end its limit (c2 - c0 at t = 0, c3 - c1 at t = 1).
pub fn curve_direction(c: &[Vec2; 4], t: f32) -> Vec2 {
    let end = if t < 0.5 { c[2] - c[0] } else { c[3] - c[1] };
    [bezier_tangent(c, t), end, c[3] - c[0]]
        .into_iter()
        .find(|d| d.length_squared() >= 1e-16)
        .map_or(Vec2::Y, Vec2::normalize)
}

/// Warped vertices in the exported layout: instance-major positions and normals (zero for
/// outliers) and whether each vertex is valid.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WarpedLayout {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub valid: Vec<bool>,
}

impl WarpedLayout {
    /// Zeroed: an outlier's position and normal are zero. Allocated zeroed rather than filled,
    /// so the pages are touched first by the threads that write them.
    pub fn with_len(n: usize) -> Self {
        use bytemuck::zeroed_vec;
        WarpedLayout { positions: zeroed_vec(n), normals: zeroed_vec(n), valid: zeroed_vec(n) }
    }

    /// As per-vertex structs (tests compare them with the CPU reference).
    pub fn vertices(&self) -> Vec<WarpedVertex> {
        (0..self.positions.len())
            .map(|i| WarpedVertex { position: self.positions[i], normal: self.normals[i], valid: self.valid[i] })
            .collect()
    }
}

/// How many of `instances` each CPU thread takes (all threads, whole instances).
pub fn instances_per_thread(instances: usize) -> usize {
    let threads = std::thread::available_parallelism().map_or(1, |t| t.get()).max(1);
    instances.div_ceil(threads).max(1)
}

/// Warps every instance of `mesh` on the CPU with all threads into the exported layout: the
/// classic path the paper compares against (uploaded every frame), and the export path on a
/// CPU adapter (`werkstatt bench export` measures both).
pub fn warp_layout_cpu(
    texels: &MatrixTexels,
    s: &WarpSettings,
    mesh: &Mesh,
    instances: &[InstanceData],
) -> WarpedLayout {
    let n = mesh.positions.len();
    let mut out = WarpedLayout::with_len(n * instances.len());
    if n == 0 || instances.is_empty() {
        return out;
    }
    let chunk = instances_per_thread(instances.len());
    let outputs =
        out.positions.chunks_mut(chunk * n).zip(out.normals.chunks_mut(chunk * n)).zip(out.valid.chunks_mut(chunk * n));
    std::thread::scope(|scope| {
        for (insts, ((positions, normals), valid)) in instances.chunks(chunk).zip(outputs) {
            scope.spawn(move || {
                for (k, inst) in insts.iter().enumerate() {
                    warp_instance_cpu(texels, s, inst, mesh, |v, w| {
                        if w.valid {
                            let i = k * n + v;
                            (positions[i], normals[i], valid[i]) = (w.position, w.normal, true);
                        }
                    });
                }
            });
        }
    });
    out
}
