//! Deferred warping, pass 1: the matrix texture of a surface (paper section 3.2, eq. 3).

use std::sync::Arc;

use crate::gpu::texture::copy_bits;
use crate::gpu::{FullscreenPass, GpuContext, GpuImage, RenderPipelineDesc, TextureDesc, read_back};
use crate::mesh::{Mesh, Vertex};
use crate::node::prelude::*;
use crate::warp::{MatrixTexels, MatrixTexture, TexelFrame};

pub static MATRIX_TEXTURE: NodeSpec = NodeSpec {
    kind: "MatrixTexture",
    category: Category::Attachment,
    doc: "Renders a surface in UV space into a matrix texture: per texel the orthonormal frame (t_u, n, t_v) and position of eq. (3). Empty texels stay zero so lookups outside the pieces are detected.",
    inputs: &[PortSpec::required(
        "surface",
        PortType::Surface,
        "The deformed surface; its UVs are the packed pattern coordinates.",
    )],
    outputs: &[
        PortSpec::output("matrix", PortType::MatrixTexture, "The matrix texture, for attachment nodes."),
        PortSpec::output("normal", PortType::Texture, "The normal column (n in rgb, position y in a), for inspection."),
        PortSpec::output("min_resolution", PortType::Scalar, "The sampling-theorem minimum: 2 / shortest UV edge."),
    ],
    params: &[
        ParamSpec::new(
            "resolution",
            ParamKind::Int { default: 512, min: 8, max: 8192 },
            "Width and height in texels (the paper used 512).",
        ),
        ParamSpec::new(
            "precision",
            ParamKind::Choice { default: "f32", options: Precision::OPTIONS },
            "Texel format: Rgba32Float, or Rgba16Float (half the memory, about 1e-3 relative position error).",
        ),
        ParamSpec::new(
            "filter_radius",
            ParamKind::Int { default: 0, min: 0, max: 8 },
            "Low-pass filter of the orientation field in texels (0 = off), against self-intersections of tall details.",
        ),
    ],
    is_output: false,
    create: || Box::new(MatrixTextureNode::default()),
};

#[derive(Default)]
pub struct MatrixTextureNode {
    filter: Option<FullscreenPass>,
    /// Where Rgba32Float cannot be rendered: the buffer its bits are copied through.
    bit_copy: Option<wgpu::Buffer>,
    /// The seam map depends only on UVs, seams and resolution, not on positions: kept across frames.
    seam_map: Option<(u64, GpuImage)>,
}

/// Gutter width of the seam map, in texels.
pub const SEAM_GUTTER_TEXELS: f32 = 2.0;

fn topology_key(mesh: &Mesh, resolution: u32) -> u64 {
    let mut h = crate::hash::fnv1a(bytemuck::cast_slice(&mesh.uvs));
    h ^= crate::hash::fnv1a(bytemuck::cast_slice(&mesh.seams)).rotate_left(17);
    h ^= crate::hash::fnv1a(bytemuck::cast_slice(&mesh.indices)).rotate_left(29);
    h ^ (resolution as u64).rotate_left(41)
}

/// The shortest triangle edge in UV space; the sampling theorem asks for at least two texels
/// across it (dissertation section 4.1.2).
pub fn min_resolution(mesh: &Mesh) -> f64 {
    let mut shortest = f32::MAX;
    for t in mesh.indices.chunks_exact(3) {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let e = (mesh.uvs[a as usize] - mesh.uvs[b as usize]).length();
            if e > 0.0 {
                shortest = shortest.min(e);
            }
        }
    }
    if shortest == f32::MAX { 0.0 } else { (2.0 / shortest as f64).ceil() }
}

impl MatrixTextureNode {
    /// Renders the matrix texture of `mesh` (pooled targets, recorded into the frame); used
    /// by the node and by benchmarks.
    pub fn render(
        &mut self,
        gpu: &GpuContext,
        mesh: &Mesh,
        resolution: u32,
        format: wgpu::TextureFormat,
        filter_radius: u32,
    ) -> anyhow::Result<MatrixTexture> {
        // Where 32-bit floats cannot be rendered (llvmpipe's GL) the passes write their bits
        // into Rgba32Uint targets, copied into the Rgba32Float texture: the same values.
        let bits = format == wgpu::TextureFormat::Rgba32Float && !gpu.formats().float32_renderable;
        let (target_format, entry) =
            if bits { (wgpu::TextureFormat::Rgba32Uint, "fs_bits") } else { (format, "fs_main") };
        let make = |name| GpuImage::target(gpu, name, resolution, resolution, target_format);
        let (col_u, col_n, col_v) = (make("matrix t_u"), make("matrix n"), make("matrix t_v"));
        let gpu_mesh = mesh.gpu(gpu);
        let formats = [target_format; 3];
        let pipeline = gpu.render_pipeline(&RenderPipelineDesc {
            fragment_entry: entry,
            ..RenderPipelineDesc::new("matrix_texture.wgsl", &[], &[Some(Vertex::layout())], &formats)
        })?;
        gpu.record(|enc| {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("matrix texture"),
                color_attachments: &[col_u.clear_attachment(), col_n.clear_attachment(), col_v.clear_attachment()],
                depth_stencil_attachment: None,
                timestamp_writes: gpu.pass_timestamps(),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&pipeline);
            pass.set_vertex_buffer(0, gpu_mesh.vertices.slice(..));
            pass.set_index_buffer(gpu_mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..gpu_mesh.index_count, 0, 0..1);
        });
        let key = topology_key(mesh, resolution);
        if self.seam_map.as_ref().is_none_or(|(k, _)| *k != key) {
            self.seam_map = Some((key, upload_seam_map(gpu, mesh, resolution)));
        }
        let seams = self.seam_map.as_ref().expect("set above").1.share();
        let mut m = MatrixTexture { col_u, col_n, col_v, seams, resolution };
        let bit_copy = &mut self.bit_copy;
        let mut as_floats = |m: MatrixTexture| {
            if !bits {
                return m;
            }
            let usage = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
            let desc = TextureDesc::d2(resolution, resolution, format, usage);
            let [u, n, v] = [&m.col_u, &m.col_n, &m.col_v].map(|src| {
                let dst = gpu.acquire("matrix column", desc);
                copy_bits(gpu, src, &dst, bit_copy);
                dst
            });
            MatrixTexture { col_u: u, col_n: n, col_v: v, seams: m.seams, resolution }
        };
        m = as_floats(m);
        if filter_radius > 0 {
            let pass =
                self.filter.get_or_insert_with(|| FullscreenPass::new("matrix_filter.wgsl").with_fragment_entry(entry));
            for dir in [[1.0f32, 0.0], [0.0, 1.0]] {
                let out = MatrixTexture {
                    seams: m.seams.share(),
                    col_u: make("matrix t_u"),
                    col_n: make("matrix n"),
                    col_v: make("matrix t_v"),
                    resolution,
                };
                let params = [dir[0], dir[1], filter_radius as f32, 0.0];
                pass.run_mrt(
                    gpu,
                    bytemuck::cast_slice(&params),
                    &[&m.col_u, &m.col_n, &m.col_v],
                    &[&out.col_u, &out.col_n, &out.col_v],
                )?;
                m = as_floats(out);
            }
        }
        Ok(m)
    }
}

crate::choice!(
    enum Precision {
        F32 = "f32",
        F16 = "f16",
    }
);

impl Node for MatrixTextureNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let mesh: Arc<Mesh> = cx.input("surface")?;
        let resolution = cx.int("resolution") as u32;
        if resolution > gpu.limits.max_texture_dimension_2d {
            return Err(NodeError::msg(format!(
                "resolution {resolution} exceeds this adapter's texture limit {}",
                gpu.limits.max_texture_dimension_2d
            )));
        }
        let min_res = min_resolution(&mesh);
        if (resolution as f64) < min_res {
            cx.warn(format!(
                "resolution {resolution} is below the sampling minimum {min_res} (2 texels across the shortest UV edge); small triangles will be undersampled"
            ));
        }
        if mesh.uvs.iter().any(|uv| uv.x < 0.0 || uv.y < 0.0 || uv.x > 1.0 || uv.y > 1.0) {
            cx.warn("some UVs lie outside [0,1]^2; those parts of the surface are not in the matrix texture");
        }
        let format = match cx.choice::<Precision>("precision") {
            Precision::F16 => gpu.formats().matrix_f16,
            Precision::F32 => wgpu::TextureFormat::Rgba32Float,
        };
        let m = self.render(gpu, &mesh, resolution, format, cx.int("filter_radius") as u32)?;
        cx.set("normal", Arc::new(m.col_n.share()));
        cx.set("matrix", Arc::new(m));
        cx.set("min_resolution", min_res);
        Ok(())
    }
}

/// Copies a matrix texture to the CPU.
pub fn read_matrix(gpu: &GpuContext, m: &MatrixTexture) -> anyhow::Result<MatrixTexels> {
    let (u, n, v) = (read_back(gpu, &m.col_u)?, read_back(gpu, &m.col_n)?, read_back(gpu, &m.col_v)?);
    let v3 = |px: &[f32], i: usize| glam::Vec3::new(px[4 * i], px[4 * i + 1], px[4 * i + 2]);
    let frames = (0..(m.resolution * m.resolution) as usize)
        .map(|i| TexelFrame {
            tu: v3(&u.rgba, i),
            n: v3(&n.rgba, i),
            tv: v3(&v.rgba, i),
            p: glam::Vec3::new(u.rgba[4 * i + 3], n.rgba[4 * i + 3], v.rgba[4 * i + 3]),
        })
        .collect();
    let seams = read_back(gpu, &m.seams)?.rgba.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
    Ok(MatrixTexels { resolution: m.resolution, frames, seams })
}

fn upload_seam_map(gpu: &GpuContext, mesh: &Mesh, resolution: u32) -> GpuImage {
    // Without seams a 1x1 placeholder (the shader checks its size) saves res^2 x 16 bytes.
    let (data, size) = if mesh.seams.is_empty() {
        (vec![[0.0f32; 4]], 1)
    } else {
        (crate::warp::seam_map(mesh, resolution, SEAM_GUTTER_TEXELS), resolution)
    };
    GpuImage::upload(gpu, "seam map", size, size, wgpu::TextureFormat::Rgba32Float, 16, bytemuck::cast_slice(&data))
}
