//! `MedianCut`: the environment map split into regions of equal energy, one light each.

use std::sync::Arc;

use glam::Vec3;

use crate::core::node::prelude::*;
use crate::ibl::cube::{dir_to_face, equirect_dir, equirect_uv};
use crate::ibl::gpu::{EnvMap, Lights};
use crate::ibl::median_cut::{Regions, median_cut};

pub static MEDIAN_CUT: NodeSpec = NodeSpec {
    kind: "MedianCut",
    category: Category::Lighting,
    doc: "Splits the environment map's cube texels into N regions of equal energy (solid-angle weighted luminance; any N), each texel in exactly one region (eq. 3.33), with one directional light per region: direction, colour (the region's integral of radiance) and solid angle. The lights cast the shadows; the PEMs carry the shading.",
    inputs: &[PortSpec::required("environment", PortType::Environment, "The map to split.")],
    outputs: &[
        PortSpec::output("lights", PortType::Lights, "One light per region, with the regions."),
        PortSpec::output(
            "regions",
            PortType::Texture,
            "The regions over the map (equirectangular), lights as dots (Fig. 3.14).",
        ),
    ],
    params: &[ParamSpec::new(
        "count",
        ParamKind::Int { default: 16, min: 1, max: 4096 },
        "Number of regions (and lights).",
    )],
    capabilities: Capabilities::NONE,
    create: || Box::new(MedianCutNode),
};

struct MedianCutNode;

impl Node for MedianCutNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let env: Arc<EnvMap> = cx.input("environment")?;
        let regions = median_cut(&env.texels, cx.int("count") as usize).map_err(|e| NodeError::msg(e.to_string()))?;
        let (w, h, rgba) = region_image(&env, &regions);
        let preview = crate::gpu::GpuImage::upload(gpu, "median cut regions", w, h, gpu.formats().ldr, 4, &rgba);
        cx.set("regions", Arc::new(preview.share()));
        let lights =
            Lights { lights: regions.lights.clone(), regions: Some(Arc::new(regions)), preview: Some(preview) };
        cx.set("lights", Arc::new(lights));
        Ok(())
    }
}

/// A distinct, stable colour per region id.
fn region_color(id: u32) -> Vec3 {
    let h = crate::core::hash::fnv1a(&id.to_le_bytes());
    Vec3::new((h & 0xff) as f32, ((h >> 8) & 0xff) as f32, ((h >> 16) & 0xff) as f32) / 255.0 * 0.7 + Vec3::splat(0.3)
}

/// The regions as an sRGB equirectangular image (2 size x size): each region's colour
/// shaded by the map's tone-mapped brightness, borders dark, each light a white dot.
fn region_image(env: &EnvMap, regions: &Regions) -> (u32, u32, Vec<u8>) {
    let size = env.size();
    let (w, h) = (2 * size.max(64), size.max(64));
    let id_at = |d: Vec3| {
        let (face, u, v) = dir_to_face(d);
        let texel = |c: f32| (((c + 1.0) * 0.5 * size as f32) as usize).min(size - 1);
        let index = env.texels.index(face, texel(u), texel(v));
        (regions.ids[index], env.texels.texels[index].truncate())
    };
    let dir_at = |x: usize, y: usize| equirect_dir((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
    let ids: Vec<(u32, Vec3)> =
        (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).map(|(x, y)| id_at(dir_at(x, y))).collect();
    let mut rgba = vec![0u8; w * h * 4];
    for y in 0..h {
        for x in 0..w {
            let (id, radiance) = ids[y * w + x];
            let border = (x + 1 < w && ids[y * w + x + 1].0 != id) || (y + 1 < h && ids[(y + 1) * w + x].0 != id);
            let lum = crate::color::luminance(radiance);
            let shade = if border { Vec3::ZERO } else { region_color(id) * (0.25 + 0.75 * lum / (1.0 + lum)) };
            let o = (y * w + x) * 4;
            for c in 0..3 {
                rgba[o + c] = (crate::color::linear_to_srgb(shade[c]) * 255.0).round() as u8;
            }
            rgba[o + 3] = 255;
        }
    }
    for light in &regions.lights {
        let (u, v) = equirect_uv(light.direction);
        let (cx, cy) = ((u * w as f32) as i64, (v * h as f32) as i64);
        for dy in -2..=2i64 {
            for dx in -2..=2i64 {
                let (x, y) = ((cx + dx).rem_euclid(w as i64) as usize, (cy + dy).clamp(0, h as i64 - 1) as usize);
                rgba[(y * w + x) * 4..(y * w + x) * 4 + 3].copy_from_slice(&[255, 255, 255]);
            }
        }
    }
    (w as u32, h as u32, rgba)
}
