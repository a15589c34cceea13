//! `BtfShading`: the deferred BTF shading of Sattler et al. 2003 (shaders/btf/btf_shading.wgsl).

use std::sync::Arc;

use crate::btf::gpu::{GpuBtf, shadow_ramp};
use crate::btf::hem::{EigenWeightsets, Visibility, mesh_frames};
use crate::core::node::prelude::*;
use crate::gpu::pass::Bindings;
use crate::gpu::{Bind, BufferRing, FullscreenPass, GpuContext, GpuImage, RenderPipelineDesc, SamplerKind};
use crate::ibl::cube::CubeImage;
use crate::ibl::gpu::{EnvMap, Lights};
use crate::ibl::shadow::{GpuLight, ShadowAtlas, gpu_lights, vsm_settings};
use crate::render::scene::{DrawItem, GBuffer};

/// Texels of eq. 6's 1D texture (the paper's 1024).
const RAMP_SIZE: usize = 1024;

pub static BTF_SHADING: NodeSpec = NodeSpec {
    kind: "BtfShading",
    category: Category::Lighting,
    doc: "Deferred BTF shading (Sattler et al. 2003) of the pixels whose material's btf_id equals material_id: view and lights in the tangent frame of the item's UVs (the G-buffer's surface target), the 4 nearest view slots (eq. 5) and per light the 4 nearest light directions (eq. 3) with bilinear ring weights, coefficients blended before one pass over the mean and eigentextures (eqs. 3-4), times exposure (eq. 11). Lights: a directional sun with eq. 6's smooth shadow boundary (alpha and a blurred 1D texture), the directional lights of a MedianCut or SunLight (their visibility from a ShadowAtlas of them, `shadows`: cast shadows), and an environment by the paper's per-vertex visibility and weight sets (HEM, eqs. 10-12) on the items of `scene`, turned in real time by `environment_rotation`, directly or through eigen-weightsets (section 5.4). The weave tiles `tiling` times per UV unit, turned by `rotation`. Other pixels show `base` (or the background colour).",
    inputs: &[
        PortSpec::required("gbuffer", PortType::GBuffer, "The G-buffer to shade."),
        PortSpec::required("btf", PortType::Btf, "The compressed BTF (Btf)."),
        PortSpec::optional(
            "base",
            PortType::Texture,
            "Linear HDR image for the pixels this node does not shade (DirectLight, IblShading); unconnected: the background colour.",
        ),
        PortSpec::optional(
            "lights",
            PortType::Lights,
            "Directional lights of an environment (MedianCut), each through the BTF; no visibility.",
        ),
        PortSpec::optional(
            "shadows",
            PortType::ShadowAtlas,
            "Variance shadow maps of the `lights` input's lights, in its order (a ShadowAtlas fed from the same MedianCut or SunLight): each light's term times its VIS, Chebyshev's bound as in IblShading (no jitter). The `sun_*` parameters' sun stays unshadowed.",
        ),
        PortSpec::optional(
            "scene",
            PortType::Scene,
            "HEM: the items lit by `environment` through per-vertex visibility and weight sets (eq. 12): those whose material's btf_id is material_id, each with its model matrix (a cuboid transform is not applied). Rebuilt when a mesh changes.",
        ),
        PortSpec::optional(
            "environment",
            PortType::Environment,
            "HEM: the probe lighting `scene`'s items (its level 0 texels); a new one recomputes only the weight sets.",
        ),
    ],
    outputs: &[PortSpec::output("image", PortType::Texture, "Linear HDR radiance.")],
    params: &[
        ParamSpec::new(
            "material_id",
            ParamKind::Int { default: 1, min: 1, max: 65535 },
            "Shades the pixels of materials whose btf_id equals this.",
        ),
        ParamSpec::new(
            "exposure",
            ParamKind::Float { default: 1.0, min: 0.0, max: 1e6 },
            "f of eq. 11: scales the result.",
        ),
        ParamSpec::new(
            "tiling",
            ParamKind::Float { default: 8.0, min: 1e-3, max: 1e5 },
            "Repeats of the BTF tile per UV unit.",
        ),
        ParamSpec::new(
            "rotation",
            ParamKind::Float { default: 0.0, min: -360.0, max: 360.0 },
            "Turns the weave on the surface, degrees from the UV's u axis towards the tile's y axis (up its images, decreasing v).",
        ),
        ParamSpec::new(
            "sun_direction",
            ParamKind::Vec3 { default: [-0.4, -1.0, -0.6] },
            "Direction the sun's light travels.",
        ),
        ParamSpec::new("sun_color", ParamKind::Color { default: [1.0, 0.96, 0.9] }, "Sun colour."),
        ParamSpec::new(
            "sun_intensity",
            ParamKind::Float { default: 3.0, min: 0.0, max: 1e5 },
            "Sun irradiance on a surface facing it (0: no sun).",
        ),
        ParamSpec::new(
            "alpha",
            ParamKind::Float { default: 15.0, min: 0.0, max: 90.0 },
            "Eq. 6's offset in degrees: the sun's boundary sits where the angle between normal and light is 90 - alpha.",
        ),
        ParamSpec::new(
            "shadow_blur",
            ParamKind::Float { default: 64.0, min: 0.0, max: 1024.0 },
            "Blur of eq. 6's 1D texture, in its 1024 texels (0: a hard boundary).",
        ),
        ParamSpec::new(
            "sun_boundary",
            ParamKind::Choice { default: "smooth", options: Boundary::OPTIONS },
            "smooth: eq. 6's boundary (alpha, shadow_blur) on the surface the interpolated normals describe; faces: the hard boundary a shadow volume gives, dark where the triangle itself faces away from the sun (the zigzag of the paper's Fig. 8, left); none: only the cosine carried to 0 at the horizon.",
        ),
        ParamSpec::new(
            "lights_boundary",
            ParamKind::Choice { default: "none", options: Boundary::OPTIONS },
            "The boundary of the `lights` input's lights, as sun_boundary: none for an environment's lights, smooth (eq. 6) for a SunLight shadowed through `shadows`.",
        ),
        ParamSpec::new(
            "environment_intensity",
            ParamKind::Float { default: 1.0, min: 0.0, max: 1e5 },
            "Scales the lights of the `lights` input and the `environment`.",
        ),
        ParamSpec::new(
            "environment_rotation",
            ParamKind::Float { default: 0.0, min: -3600.0, max: 3600.0 },
            "HEM: turns the environment about +Y by this many degrees (as EnvironmentMap's rotation), in real time: see rotation_steps.",
        ),
        ParamSpec::new(
            "rotation_steps",
            ParamKind::Int { default: 0, min: 0, max: 360 },
            "HEM: 0 turns the probe itself (resampled, then light sums and eq. 12's product again, per new angle); A > 0 decomposes the weight sets of A rotations in 360/A degree steps once into eigen-weightsets (section 5.4, eq. 13), and each angle then sums eigen_sets of them, their weights o_ak interpolated between steps.",
        ),
        ParamSpec::new(
            "eigen_sets",
            ParamKind::Int { default: 5, min: 1, max: 360 },
            "HEM with rotation_steps: the eigen-weightsets kept (e; the paper's 5), at most rotation_steps.",
        ),
        ParamSpec::new(
            "hemicube",
            ParamKind::Int { default: 16, min: 2, max: 128 },
            "HEM: resolution of the per-vertex visibility hemicubes (3 res^2 rays per vertex; even).",
        ),
        ParamSpec::new(
            "background",
            ParamKind::Color { default: [0.05, 0.05, 0.06] },
            "Colour of the pixels not shaded here when `base` is unconnected.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(BtfShadingNode::default()),
};

crate::choice!(
    enum Boundary {
        Smooth = "smooth",
        Faces = "faces",
        None = "none",
    }
);

impl Boundary {
    /// The shader's code in `Light::dir.w`: 0 none, 1 eq. 6, 2 the triangles' own facing.
    fn code(self) -> f32 {
        match self {
            Boundary::None => 0.0,
            Boundary::Smooth => 1.0,
            Boundary::Faces => 2.0,
        }
    }
}

/// shaders/btf/btf_shading.wgsl `Params`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    inv_view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    size: [f32; 4],
    btf: [f32; 4],
    tiling: [f32; 4],
    background: [f32; 4],
    rings: [[f32; 4]; crate::btf::gpu::MAX_RINGS],
}

struct BtfShadingNode {
    pass: FullscreenPass,
    lights: BufferRing,
    /// Eq. 6's texture and the blur it was made with.
    ramp: Option<(f32, GpuImage)>,
    /// The HEM's per-vertex data, and the bindings of its triangle-id pass.
    hem: Option<Hem>,
    ids_pass: Bindings,
}

impl Default for BtfShadingNode {
    fn default() -> Self {
        BtfShadingNode {
            pass: FullscreenPass::new("btf_shading.wgsl"),
            lights: BufferRing::new("btf lights", wgpu::BufferUsages::STORAGE),
            ramp: None,
            hem: None,
            ids_pass: Bindings::new(wgpu::ShaderStages::VERTEX),
        }
    }
}

/// Environment light by the paper's HEM for the items of `scene`: visibility per vertex (kept
/// while the meshes, their transforms, the rotation and the hemicube stay), and the weight sets
/// U of eq. 12 on the GPU (recomputed for a new environment or BTF).
struct Hem {
    /// The inputs the keys hash the addresses of, held so that a new input cannot take a freed
    /// one's address and match a stale key.
    _held: (Vec<Arc<crate::mesh::Mesh>>, Arc<EnvMap>, Arc<GpuBtf>),
    visibility_key: u64,
    visibility: Vec<Visibility>,
    /// Section 5.4's eigen-weightsets per item, and the key of the inputs they were made from.
    eigen: Option<(u64, Arc<Vec<EigenWeightsets>>)>,
    sets_key: u64,
    /// Per triangle corner: its world position (xyz, 1), and its vertex in `sets`.
    corners: wgpu::Buffer,
    vertices: wgpu::Buffer,
    triangles: u32,
    /// U of every vertex: view slot, component, channel (f32).
    sets: wgpu::Buffer,
}

/// HEM's settings: the weave's rotation on the surface (radians), the hemicube's resolution,
/// and how the environment turns about +Y: by `degrees`, directly (steps 0: the probe
/// resampled, light sums and U again) or through the eigen-weightsets of `steps` rotations
/// (section 5.4), keeping `eigen_sets` of them.
#[derive(Clone, Copy)]
struct HemSettings {
    weave_rotation: f32,
    hemicube: usize,
    degrees: f32,
    steps: usize,
    eigen_sets: usize,
}

/// shaders/btf/btf_hem_ids.wgsl `Params`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct IdParams {
    view_proj: [[f32; 4]; 4],
}

fn hash_of(words: impl IntoIterator<Item = u64>) -> u64 {
    let bytes: Vec<u8> = words.into_iter().flat_map(u64::to_le_bytes).collect();
    crate::core::hash::fnv1a(&bytes)
}

impl BtfShadingNode {
    /// Brings the HEM data up to date for `items` under `env` (CPU: visibility rays, light sums,
    /// eq. 12's product; all cores).
    fn update_hem(
        &mut self,
        gpu: &GpuContext,
        items: &[&DrawItem],
        env: &Arc<EnvMap>,
        btf: &Arc<GpuBtf>,
        turn: HemSettings,
    ) -> Result<(), NodeError> {
        let (rotation, hemicube) = (turn.weave_rotation, turn.hemicube);
        if !hemicube.is_multiple_of(2) {
            return Err(NodeError::msg(format!("parameter \"hemicube\" must be even, not {hemicube}")));
        }
        let geometry = items.iter().flat_map(|item| {
            let model = item.model.to_cols_array().map(|x| u64::from(x.to_bits()));
            std::iter::once(Arc::as_ptr(&item.mesh) as u64).chain(model)
        });
        let visibility_key = hash_of(geometry.chain([
            u64::from(rotation.to_bits()),
            hemicube as u64,
            env.size() as u64,
            btf.sampling.len() as u64,
        ]));
        let inputs_key = hash_of([visibility_key, Arc::as_ptr(env) as u64, Arc::as_ptr(btf) as u64]);
        let eigen_key = hash_of([inputs_key, turn.steps as u64, turn.eigen_sets as u64]);
        let sets_key = hash_of([eigen_key, u64::from(turn.degrees.to_bits())]);
        if self.hem.as_ref().is_some_and(|h| h.sets_key == sets_key) {
            return Ok(());
        }
        let failed = |e: anyhow::Error| NodeError::msg(format!("environment light (HEM): {e:#}"));
        // The same geometry keeps its visibility and corner buffers; the same inputs and steps
        // keep the eigen-weightsets, so a new angle only sums them and rewrites `sets`.
        let mut kept = self.hem.take().filter(|h| h.visibility_key == visibility_key);
        let visibility = match &mut kept {
            Some(h) => std::mem::take(&mut h.visibility),
            None => items
                .iter()
                .map(|item| {
                    let (positions, frames) = mesh_frames(&item.mesh, item.model, f64::from(rotation));
                    Visibility::compute(&positions, &frames, &item.mesh.indices, &btf.sampling, hemicube, env.size(), 0)
                })
                .collect::<anyhow::Result<Vec<_>>>()
                .map_err(failed)?,
        };
        // Section 5.4: with steps, the weight sets of `steps` rotations decomposed once into
        // eigen-weightsets per item, then each rotation is a sum of them (eq. 13).
        let eigen = match kept.as_ref().and_then(|h| h.eigen.clone()).filter(|(key, _)| *key == eigen_key) {
            Some(e) if turn.steps > 0 => Some(e),
            _ if turn.steps > 0 => {
                let step = 360.0 / turn.steps as f32;
                let turned: Vec<Arc<CubeImage>> = (0..turn.steps)
                    .map(|a| if a == 0 { env.texels.clone() } else { Arc::new(env.texels.rotated_y(a as f32 * step)) })
                    .collect();
                let sets = visibility
                    .iter()
                    .map(|vis| {
                        let sums: Vec<Vec<f32>> =
                            turned.iter().map(|cube| vis.light_sums(cube, 0)).collect::<anyhow::Result<_>>()?;
                        EigenWeightsets::new(&btf.table, &sums, turn.eigen_sets.min(turn.steps), 0)
                    })
                    .collect::<anyhow::Result<Vec<_>>>()
                    .map_err(failed)?;
                Some((eigen_key, Arc::new(sets)))
            }
            _ => None,
        };
        let turned_env = match (&eigen, turn.degrees) {
            (None, d) if d != 0.0 => Arc::new(env.texels.rotated_y(d)),
            _ => env.texels.clone(),
        };
        let set_len = btf.table.set_len();
        let row = btf.table.views * btf.table.per_slot;
        let mut sets = Vec::new();
        for (index, vis) in visibility.iter().enumerate() {
            let u = match &eigen {
                Some((_, per_item)) => {
                    per_item[index].weight_set_at(f64::from(turn.degrees) * turn.steps as f64 / 360.0, 0)
                }
                None => btf.table.weight_sets(&vis.light_sums(&turned_env, 0).map_err(failed)?, 0),
            };
            // Channels innermost: the values a pixel reads per corner and view slot lie together.
            for set in u.chunks_exact(set_len) {
                sets.extend((0..row).flat_map(|jk| [set[jk], set[row + jk], set[2 * row + jk]]));
            }
        }
        let bytes = (sets.len() * 4) as u64;
        let limit = gpu.limits.max_storage_buffer_binding_size;
        if bytes > limit {
            return Err(NodeError::msg(format!(
                "environment light (HEM): the weight sets of {} vertices take {bytes} bytes, more than the device's storage binding limit of {limit}: fewer vertices or components",
                sets.len() / set_len
            )));
        }
        // A storage binding must not be empty.
        sets.resize(sets.len().max(1), 0.0);
        let storage = wgpu::BufferUsages::STORAGE;
        let (corners, vertices, triangles, sets) = match kept {
            Some(h) if h.sets.size() == (sets.len() * 4) as u64 => {
                gpu.queue.write_buffer(&h.sets, 0, bytemuck::cast_slice(&sets));
                (h.corners, h.vertices, h.triangles, h.sets)
            }
            _ => {
                let (mut corners, mut vertices) = (Vec::new(), Vec::new());
                let mut first = 0u32;
                for item in items {
                    for &i in &item.mesh.indices {
                        corners.push(item.model.transform_point3(item.mesh.positions[i as usize]).extend(1.0));
                        vertices.push(first + i);
                    }
                    first += item.mesh.positions.len() as u32;
                }
                let triangles = (vertices.len() / 3) as u32;
                corners.resize(corners.len().max(1), glam::Vec4::ZERO);
                vertices.resize(vertices.len().max(1), 0);
                (
                    gpu.create_buffer_init("btf hem corners", bytemuck::cast_slice(&corners), storage),
                    gpu.create_buffer_init("btf hem vertices", bytemuck::cast_slice(&vertices), storage),
                    triangles,
                    gpu.create_buffer_init(
                        "btf hem sets",
                        bytemuck::cast_slice(&sets),
                        storage | wgpu::BufferUsages::COPY_DST,
                    ),
                )
            }
        };
        self.hem = Some(Hem {
            _held: (items.iter().map(|item| item.mesh.clone()).collect(), env.clone(), btf.clone()),
            visibility_key,
            visibility,
            eigen,
            sets_key,
            corners,
            vertices,
            triangles,
            sets,
        });
        Ok(())
    }

    /// Per pixel, the HEM triangle it shows and its barycentrics (shaders/btf/btf_hem_ids.wgsl).
    fn draw_ids(&mut self, gpu: &GpuContext, g: &GBuffer) -> Result<GpuImage, NodeError> {
        let hem = self.hem.as_ref().expect("updated before");
        let (w, h) = (g.width(), g.height());
        let ids = GpuImage::target(gpu, "btf hem ids", w, h, wgpu::TextureFormat::Rgba32Uint);
        let depth = GpuImage::target(gpu, "btf hem depth", w, h, gpu.formats().depth);
        let params = IdParams { view_proj: g.view.view_proj.to_cols_array_2d() };
        let binds = [Bind::Uniform(bytemuck::bytes_of(&params)), Bind::Storage(&hem.corners)];
        let layout = self.ids_pass.layout(gpu, &binds);
        let formats = [wgpu::TextureFormat::Rgba32Uint];
        let pipeline = gpu
            .render_pipeline(&RenderPipelineDesc {
                depth: Some((gpu.formats().depth, wgpu::CompareFunction::Less)),
                ..RenderPipelineDesc::new("btf_hem_ids.wgsl", &[Some(&layout)], &[], &formats)
            })
            .map_err(|e| NodeError::msg(e.to_string()))?;
        let group = self.ids_pass.bind_group(gpu, &layout, &binds);
        let vertices = 3 * hem.triangles;
        gpu.record(|enc| {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("btf hem ids"),
                color_attachments: &[ids.clear_attachment()],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth.view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: gpu.pass_timestamps(),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.draw(0..vertices, 0..1);
        });
        Ok(ids)
    }
}

impl Node for BtfShadingNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let g: Arc<GBuffer> = cx.input("gbuffer")?;
        let btf: Arc<GpuBtf> = cx.input("btf")?;
        let base: Option<Arc<GpuImage>> = cx.optional("base");
        let env: Option<Arc<Lights>> = cx.optional("lights");
        let hem_scene: Option<Arc<Vec<DrawItem>>> = cx.optional("scene");
        let probe: Option<Arc<EnvMap>> = cx.optional("environment");
        let (w, h) = (g.width(), g.height());
        if let Some(b) = &base
            && (b.width, b.height) != (w, h)
        {
            return Err(NodeError::msg(format!(
                "input \"base\" is {}x{}, the G-buffer {w}x{h}: shade the same view",
                b.width, b.height
            )));
        }
        let shadows: Option<Arc<ShadowAtlas>> = cx.optional("shadows");
        let mut lights = Vec::new();
        let sun = cx.vec3("sun_color") * cx.f32("sun_intensity");
        if sun.max_element() > 0.0 {
            let towards = -cx
                .vec3("sun_direction")
                .try_normalize()
                .ok_or_else(|| NodeError::msg("parameter \"sun_direction\" must not be zero"))?;
            let boundary = cx.choice::<Boundary>("sun_boundary").code();
            lights.push(GpuLight::unshadowed(towards.extend(boundary).to_array(), sun.extend(0.0).to_array()));
        }
        let scale = cx.f32("environment_intensity");
        let boundary = cx.choice::<Boundary>("lights_boundary").code();
        let env_lights = env.as_ref().map_or(&[][..], |e| &e.lights[..]);
        lights.extend(gpu_lights(env_lights, shadows.as_deref(), boundary, scale).map_err(NodeError::msg)?);
        let count = lights.len();
        // A storage binding must not be empty.
        lights.resize(count.max(1), bytemuck::Zeroable::zeroed());
        let blur = cx.f32("shadow_blur");
        if self.ramp.as_ref().is_none_or(|(b, _)| *b != blur) {
            let bits: Vec<u16> =
                shadow_ramp(RAMP_SIZE, blur).iter().map(|&x| half::f16::from_f32(x).to_bits()).collect();
            let image = GpuImage::upload(
                gpu,
                "btf shadow ramp",
                RAMP_SIZE as u32,
                1,
                wgpu::TextureFormat::R16Float,
                2,
                bytemuck::cast_slice(&bits),
            );
            self.ramp = Some((blur, image));
        }
        let rotation = cx.f32("rotation").to_radians();
        let material_id = cx.int("material_id");
        let ids = match (&hem_scene, &probe) {
            (Some(scene), Some(probe)) => {
                let items: Vec<&DrawItem> =
                    scene.iter().filter(|item| i64::from(item.material.btf_id) == material_id).collect();
                if items.is_empty() {
                    return Err(NodeError::msg(format!(
                        "no item of input \"scene\" has a material with btf_id {material_id} (parameter \"material_id\")"
                    )));
                }
                let turn = HemSettings {
                    weave_rotation: rotation,
                    hemicube: cx.int("hemicube") as usize,
                    degrees: cx.f32("environment_rotation"),
                    steps: cx.int("rotation_steps") as usize,
                    eigen_sets: cx.int("eigen_sets") as usize,
                };
                self.update_hem(gpu, &items, probe, &btf, turn)?;
                Some(self.draw_ids(gpu, &g)?)
            }
            (None, None) => {
                self.hem = None;
                None
            }
            _ => {
                return Err(NodeError::msg(
                    "inputs \"scene\" and \"environment\" light by the environment together (HEM): connect both or neither",
                ));
            }
        };
        let (_, ramp) = self.ramp.as_ref().expect("made above");
        let background = cx.vec3("background");
        let params = Params {
            inv_view_proj: g.view.inv_view_proj.to_cols_array_2d(),
            eye: g.view.eye.extend(1.0).to_array(),
            size: [w as f32, h as f32, scale, material_id as f32],
            btf: {
                let [min_variance, bleed, bias] = vsm_settings(shadows.as_deref());
                [min_variance, bleed, bias, cx.f32("exposure")]
            },
            tiling: [cx.f32("tiling"), rotation.cos(), rotation.sin(), cx.f32("alpha").to_radians()],
            background: background.extend(0.0).to_array(),
            rings: btf.rings_uniform(),
        };
        let light_buffer = self.lights.write(gpu, bytemuck::cast_slice(&lights)).clone();
        let out = GpuImage::target(gpu, "btf shading", w, h, gpu.formats().hdr);
        let binds = [
            Bind::Uniform(bytemuck::bytes_of(&params)),
            Bind::Texture(&g.normal),
            Bind::Texture(&g.depth),
            Bind::Texture(&g.surface),
            // Unbound: the normal stands in (never read).
            Bind::Texture(base.as_deref().unwrap_or(&g.normal)),
            Bind::Texture(&btf.images),
            Bind::Sampler(SamplerKind::LinearRepeat),
            Bind::Texture(ramp),
            Bind::Sampler(SamplerKind::LinearClamp),
            Bind::Storage(&btf.coeffs),
            Bind::Storage(&light_buffer),
            // Unbound: the surface and the light buffer stand in (never read).
            Bind::Texture(ids.as_ref().unwrap_or(&g.surface)),
            Bind::Storage(self.hem.as_ref().map_or(&light_buffer, |h| &h.vertices)),
            Bind::Storage(self.hem.as_ref().map_or(&light_buffer, |h| &h.sets)),
            // Unbound: the normal stands in (never read).
            Bind::Texture(shadows.as_ref().map_or(&g.normal, |a| &a.atlas)),
            Bind::Storage(&btf.affine),
        ];
        let constants = [
            ("DIRECTIONS", btf.sampling.len() as u32),
            ("PER_SLOT", btf.layers_per_slot() as u32),
            ("RINGS", btf.sampling.rings.len() as u32),
            ("LIGHTS", count as u32),
            ("BASE", u32::from(base.is_some())),
            ("HEM", u32::from(ids.is_some())),
            ("SHADOWS", u32::from(shadows.is_some())),
        ];
        self.pass.draw_specialized(gpu, &binds, &[&out.view], &[out.format], &constants)?;
        cx.count("lights", count);
        cx.set("image", Arc::new(out));
        Ok(())
    }
}
