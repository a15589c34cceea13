//! Deferred warping, pass 1: the matrix texture of a surface (paper section 3.2, eq. 3).

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::gpu::texture::copy_bits;
use crate::gpu::{FullscreenPass, GpuContext, GpuImage, RenderPipelineDesc, TextureDesc};
use crate::mesh::{Mesh, Vertex};
use crate::render::scene::DrawItem;
use crate::tessellation::TessMesh;
use crate::warp::MatrixTexture;

pub static MATRIX_TEXTURE: NodeSpec = NodeSpec {
    kind: "MatrixTexture",
    category: Category::Attachment,
    doc: "Renders a surface in UV space into a matrix texture: per texel the orthonormal frame (t_u, n, t_v) and position of eq. (3). Empty texels stay zero so lookups outside the pieces are detected.",
    inputs: &[
        PortSpec::required(
            "surface",
            PortType::Surface,
            "The deformed surface; its UVs are the packed pattern coordinates.",
        ),
        PortSpec::optional(
            "refined",
            PortType::Scene,
            "The scene of a Tessellate node refining this surface: the matrix texture then rasterizes the refined (PN-smoothed) GPU mesh, so attachments sit on the surface the G-buffer draws. Needs translate, rotate and scale at their defaults (transform the surface before Tessellate).",
        ),
        PortSpec::optional(
            "drawn",
            PortType::Scene,
            "The scene of the Draw that shows this surface (or any scene holding it): the matrix texture takes that item's transform, so surface and attachments cannot disagree. With it, leave translate, rotate and scale at their defaults (set, they must equal the Draw's).",
        ),
    ],
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
            "Low-pass filter of the orientation field in texels (0 = off), within each pattern piece, against self-intersections of tall details.",
        ),
        ParamSpec::new(
            "flip_left_handed",
            ParamKind::Bool { default: false },
            "Flip t_v on pattern pieces whose UVs are mirrored ((t_u x n) . t_v < 0), so attachments there are not mirrored.",
        ),
        ParamSpec::new(
            "mirrored_ok",
            ParamKind::Bool { default: false },
            "The mirrored UVs are known and harmless (no attachment that reads backwards lands there): no warning about them.",
        ),
        ParamSpec::new(
            "translate",
            ParamKind::Vec3 { default: [0.0, 0.0, 0.0] },
            "The surface's model transform, as on the Draw that shows it (applied last); better: link the Draw's scene into `drawn`.",
        ),
        crate::nodes::mesh::geometry::ROTATE,
        crate::nodes::mesh::geometry::SCALE,
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(MatrixTextureNode::default()),
};

#[derive(Default)]
pub struct MatrixTextureNode {
    filter: Option<FullscreenPass>,
    /// Where Rgba32Float cannot be rendered: the buffer its bits are copied through.
    bit_copy: Option<wgpu::Buffer>,
    /// The seam map depends only on UVs, seams and resolution, not on positions: kept across frames.
    seam_map: Option<(u64, GpuImage)>,
    /// The piece map (piece_map.wgsl) for the filter, by the same key.
    piece_map: Option<(u64, GpuImage)>,
}

/// Gutter width of the seam map, in texels.
pub const SEAM_GUTTER_TEXELS: f32 = 2.0;

fn topology_key(mesh: &Mesh, resolution: u32) -> u64 {
    let mut h = crate::core::hash::fnv1a(bytemuck::cast_slice(&mesh.uvs));
    h ^= crate::core::hash::fnv1a(bytemuck::cast_slice(&mesh.seams)).rotate_left(17);
    h ^= crate::core::hash::fnv1a(bytemuck::cast_slice(&mesh.indices)).rotate_left(29);
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
        refined: Option<&TessMesh>,
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
            fragment_entry: Some(entry),
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
            match refined {
                // Written by this frame's compute pass, in the mesh's vertex layout: its counts
                // never come back to the CPU. Its pieces have the coarse triangles' UV outlines
                // (refinement keeps edges straight in UV), so the seam and piece maps still hold.
                Some(t) => {
                    pass.set_vertex_buffer(0, t.vertices.slice(..));
                    pass.set_index_buffer(t.indices.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed_indirect(&t.indirect, 0);
                }
                None => {
                    pass.set_vertex_buffer(0, gpu_mesh.vertices.slice(..));
                    pass.set_index_buffer(gpu_mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed(0..gpu_mesh.index_count, 0, 0..1);
                }
            }
        });
        let key = topology_key(mesh, resolution);
        if self.seam_map.as_ref().is_none_or(|(k, _)| *k != key) {
            self.seam_map = Some((key, upload_seam_map(gpu, mesh, resolution)));
        }
        let seams = self.seam_map.as_ref().expect("set above").1.share();
        let mut m = MatrixTexture { col_u, col_n, col_v, seams, resolution, placed_on: None };
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
            MatrixTexture { col_u: u, col_n: n, col_v: v, seams: m.seams, resolution, placed_on: None }
        };
        m = as_floats(m);
        if filter_radius > 0 {
            if self.piece_map.as_ref().is_none_or(|(k, _)| *k != key) {
                self.piece_map = Some((key, render_piece_map(gpu, mesh, resolution)?));
            }
            let pieces = self.piece_map.as_ref().expect("set above").1.share();
            let pass =
                self.filter.get_or_insert_with(|| FullscreenPass::new("matrix_filter.wgsl").with_fragment_entry(entry));
            for dir in [[1.0f32, 0.0], [0.0, 1.0]] {
                let out = MatrixTexture {
                    seams: m.seams.share(),
                    col_u: make("matrix t_u"),
                    col_n: make("matrix n"),
                    col_v: make("matrix t_v"),
                    resolution,
                    placed_on: None,
                };
                let params = [dir[0], dir[1], filter_radius as f32, 0.0];
                pass.run_mrt(
                    gpu,
                    bytemuck::cast_slice(&params),
                    &[&m.col_u, &m.col_n, &m.col_v, &pieces],
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
        // The surface in world space: moved by its model transform, as the Draw that shows it.
        let own = crate::nodes::mesh::geometry::model_matrix(cx)?;
        let model = match cx.optional::<Arc<Vec<DrawItem>>>("drawn") {
            Some(scene) => drawn_transform(&scene, &mesh, own)?,
            None => own,
        };
        let surface = mesh.clone();
        let refined = match cx.optional::<Arc<Vec<DrawItem>>>("refined") {
            Some(scene) => Some(refined_mesh(&scene, &mesh, model)?),
            None => None,
        };
        let mut mesh: Arc<Mesh> = if model == glam::Mat4::IDENTITY {
            mesh
        } else {
            Arc::new(crate::nodes::mesh::geometry::transform_mesh(&mesh, model))
        };
        let hands = handedness(&mesh, resolution);
        let flip = cx.bool("flip_left_handed");
        let left: Vec<&PieceHandedness> = hands.iter().filter(|h| h.left_texels >= 0.5).collect();
        if !left.is_empty() && !cx.bool("mirrored_ok") {
            let list: Vec<String> = left
                .iter()
                .map(|h| format!("piece {}: {:.0} of {:.0}", h.piece, h.left_texels, h.left_texels + h.right_texels))
                .collect();
            let total: f64 = left.iter().map(|h| h.left_texels).sum();
            let what = format!(
                "about {total:.0} texels have left-handed (mirrored) UVs, (t_u x n) . t_v < 0 ({})",
                list.join(", ")
            );
            cx.warn(if flip {
                format!("{what}; t_v is flipped on the pieces where they are the majority")
            } else {
                format!(
                    "{what}: attachments placed there (buttons, decals, stickers, fur) come out mirrored, so text and \
                     logos read backwards; where none lands it does not matter: set mirrored_ok to silence this, or \
                     flip_left_handed to flip t_v on those pieces"
                )
            });
        }
        let flipped: Vec<u32> = if flip {
            hands.iter().filter(|h| h.left_texels > h.right_texels).map(|h| h.piece).collect()
        } else {
            vec![]
        };
        if !flipped.is_empty() && refined.is_some() {
            return Err(NodeError::msg(
                "flip_left_handed cannot flip t_v on the refined mesh (it is computed on the GPU); unlink `refined` or mirror the UVs of the left-handed pieces",
            ));
        }
        if !flipped.is_empty() {
            let mut m = (*mesh).clone();
            for (i, t) in m.tangents_v.iter_mut().enumerate() {
                if flipped.contains(&m.piece_ids.get(i).copied().unwrap_or(0)) {
                    *t = -*t;
                }
            }
            mesh = Arc::new(m);
        }
        let format = match cx.choice::<Precision>("precision") {
            Precision::F16 => gpu.formats().matrix_f16,
            Precision::F32 => wgpu::TextureFormat::Rgba32Float,
        };
        let filter_radius = cx.int("filter_radius") as u32;
        let m = self.render(
            gpu,
            &mesh,
            resolution,
            format,
            filter_radius,
            refined.as_ref().and_then(DrawItem::kind_as::<TessMesh>),
        )?;
        let m = MatrixTexture { placed_on: Some((surface, model)), ..m };
        cx.set("normal", Arc::new(m.col_n.share()));
        cx.set("matrix", Arc::new(m));
        cx.set("min_resolution", min_res);
        Ok(())
    }
}

/// The transform of the item in `scene` that draws `surface` (the `drawn` input); an error
/// where none does, where it is drawn with several transforms, or where the node's own
/// parameters give another one.
fn drawn_transform(scene: &[DrawItem], surface: &Arc<Mesh>, own: glam::Mat4) -> Result<glam::Mat4, NodeError> {
    use crate::render::scene::{describe_transform, same_transform};
    let models: Vec<glam::Mat4> = scene.iter().filter(|i| i.draws(surface)).map(|i| i.model).collect();
    let Some(&model) = models.first() else {
        return Err(NodeError::msg(format!(
            "drawn: none of the scene's {} items draws this surface; link the scene of the Draw whose mesh is the surface linked here",
            scene.len()
        )));
    };
    if let Some(other) = models.iter().find(|m| !same_transform(**m, model)) {
        return Err(NodeError::msg(format!(
            "drawn: the scene draws this surface {} times with different transforms ({} and {}); link the scene of the one Draw the attachments belong on",
            models.len(),
            describe_transform(model),
            describe_transform(*other)
        )));
    }
    if own != glam::Mat4::IDENTITY && !same_transform(own, model) {
        return Err(NodeError::msg(format!(
            "two transforms disagree: translate, rotate and scale give {} but the drawn surface has {}; clear them (the drawn input gives the transform) or unlink drawn",
            describe_transform(own),
            describe_transform(model)
        )));
    }
    Ok(model)
}

/// The GPU mesh a Tessellate node made of `surface`, from its scene on the `refined` input.
fn refined_mesh(scene: &[DrawItem], surface: &Arc<Mesh>, model: glam::Mat4) -> Result<DrawItem, NodeError> {
    let Some(item) = scene.iter().find(|i| i.kind_as::<TessMesh>().is_some()) else {
        return Err(NodeError::msg(
            "refined: the scene holds no GPU-refined mesh (link a Tessellate node's scene; its per_pixel mode does not refine)",
        ));
    };
    let coarse = &item.mesh;
    // The same upstream output in the usual wiring: no per-frame comparison of the arrays.
    let same = Arc::ptr_eq(coarse, surface)
        || (coarse.indices == surface.indices && coarse.uvs == surface.uvs && coarse.positions == surface.positions);
    if !same {
        return Err(NodeError::msg(format!(
            "refined: the Tessellate node refines another mesh ({} vertices, {} triangles) than this surface ({} vertices, {} triangles); link the same surface into both",
            coarse.positions.len(),
            coarse.triangle_count(),
            surface.positions.len(),
            surface.triangle_count()
        )));
    }
    if model != glam::Mat4::IDENTITY {
        return Err(NodeError::msg(
            "refined: translate, rotate and scale move the coarse surface only; transform the mesh before the Tessellate node instead",
        ));
    }
    Ok(item.clone())
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

/// Texels of one pattern piece by the handedness of its frames.
#[derive(Clone, Debug, PartialEq)]
pub struct PieceHandedness {
    pub piece: u32,
    /// Texels (UV area x resolution^2) where (t_u x n) . t_v < 0: a mirrored parametrization.
    pub left_texels: f64,
    pub right_texels: f64,
}

/// Each piece's texels by handedness at `resolution`, from its triangles: the sign of
/// (t_u x n) . t_v of the vertex frames at the centroid (Gram-Schmidt in matrix_texture.wgsl
/// keeps that sign), weighted by the triangle's UV area.
pub fn handedness(mesh: &Mesh, resolution: u32) -> Vec<PieceHandedness> {
    let mut out: Vec<PieceHandedness> = Vec::new();
    let texels = (resolution as f64).powi(2);
    for t in mesh.indices.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| i as usize);
        let sum = |v: &[glam::Vec3]| v[a] + v[b] + v[c];
        let (tu, n, tv) = (sum(&mesh.tangents_u), sum(&mesh.normals), sum(&mesh.tangents_v));
        let (e1, e2) = (mesh.uvs[b] - mesh.uvs[a], mesh.uvs[c] - mesh.uvs[a]);
        let area = 0.5 * (e1.x * e2.y - e1.y * e2.x).abs() as f64 * texels;
        let piece = mesh.piece_ids.get(a).copied().unwrap_or(0);
        let i = match out.iter().position(|h| h.piece == piece) {
            Some(i) => i,
            None => {
                out.push(PieceHandedness { piece, left_texels: 0.0, right_texels: 0.0 });
                out.len() - 1
            }
        };
        if tu.cross(n).dot(tv) < 0.0 {
            out[i].left_texels += area;
        } else {
            out[i].right_texels += area;
        }
    }
    out.sort_by_key(|h| h.piece);
    out
}

/// The piece map of `mesh` (piece_map.wgsl); a 1x1 placeholder for a mesh of one piece.
fn render_piece_map(gpu: &GpuContext, mesh: &Mesh, resolution: u32) -> anyhow::Result<GpuImage> {
    let format = gpu.formats().matrix_f16;
    let first = mesh.piece_ids.first().copied().unwrap_or(0);
    if mesh.piece_ids.iter().all(|&p| p == first) {
        let one = [0.0f32; 4];
        return Ok(GpuImage::upload(
            gpu,
            "piece map",
            1,
            1,
            wgpu::TextureFormat::Rgba32Float,
            16,
            bytemuck::cast_slice(&one),
        ));
    }
    let vertices: Vec<[f32; 3]> =
        mesh.uvs.iter().zip(&mesh.piece_ids).map(|(uv, &p)| [uv.x, uv.y, p as f32 + 1.0]).collect();
    let buffer = gpu.upload_pooled("piece map vertices", bytemuck::cast_slice(&vertices), wgpu::BufferUsages::VERTEX);
    let gpu_mesh = mesh.gpu(gpu);
    let target = GpuImage::target(gpu, "piece map", resolution, resolution, format);
    let attributes = wgpu::vertex_attr_array![0 => Float32x3];
    let layout =
        wgpu::VertexBufferLayout { array_stride: 12, step_mode: wgpu::VertexStepMode::Vertex, attributes: &attributes };
    let formats = [format];
    let pipeline = gpu.render_pipeline(&RenderPipelineDesc::new("piece_map.wgsl", &[], &[Some(layout)], &formats))?;
    gpu.record(|enc| {
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("piece map"),
            color_attachments: &[target.clear_attachment()],
            depth_stencil_attachment: None,
            timestamp_writes: gpu.pass_timestamps(),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_vertex_buffer(0, buffer.slice(..));
        pass.set_index_buffer(gpu_mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..gpu_mesh.index_count, 0, 0..1);
    });
    Ok(target)
}
