//! WGSL sources, one file per pass under `shaders/`, embedded in the binary. A line
//! `// #include "name.wgsl"` is replaced by that file, so passes share code (the G-buffer
//! output, the deferred-warping transform) without copies.

use anyhow::{Context as _, bail};

const EMBEDDED: &[(&str, &str)] = &[
    ("vertex_in.wgsl", include_str!("../../shaders/vertex_in.wgsl")),
    ("object.wgsl", include_str!("../../shaders/object.wgsl")),
    ("gbuffer_common.wgsl", include_str!("../../shaders/gbuffer_common.wgsl")),
    ("depth.wgsl", include_str!("../../shaders/depth.wgsl")),
    ("depth_readback.wgsl", include_str!("../../shaders/depth_readback.wgsl")),
    ("gbuffer.wgsl", include_str!("../../shaders/gbuffer.wgsl")),
    ("fullscreen.wgsl", include_str!("../../shaders/fullscreen.wgsl")),
    ("direct_light.wgsl", include_str!("../../shaders/direct_light.wgsl")),
    ("tonemap.wgsl", include_str!("../../shaders/tonemap.wgsl")),
    ("image_difference.wgsl", include_str!("../../shaders/image_difference.wgsl")),
    ("display.wgsl", include_str!("../../shaders/display.wgsl")),
    ("matrix_out.wgsl", include_str!("../../shaders/matrix_out.wgsl")),
    ("matrix_texture.wgsl", include_str!("../../shaders/matrix_texture.wgsl")),
    ("matrix_filter.wgsl", include_str!("../../shaders/matrix_filter.wgsl")),
    ("piece_map.wgsl", include_str!("../../shaders/piece_map.wgsl")),
    ("warp.wgsl", include_str!("../../shaders/warp.wgsl")),
    ("tessellate.wgsl", include_str!("../../shaders/tessellate.wgsl")),
    ("pn.wgsl", include_str!("../../shaders/pn.wgsl")),
    ("gbuffer_pn.wgsl", include_str!("../../shaders/gbuffer_pn.wgsl")),
    ("instance_in.wgsl", include_str!("../../shaders/instance_in.wgsl")),
    ("item_in.wgsl", include_str!("../../shaders/item_in.wgsl")),
    ("attach.wgsl", include_str!("../../shaders/attach.wgsl")),
    ("attach_export.wgsl", include_str!("../../shaders/attach_export.wgsl")),
    ("attach_resolve.wgsl", include_str!("../../shaders/attach_resolve.wgsl")),
    ("cube.wgsl", include_str!("../../shaders/cube.wgsl")),
    ("pem_filter.wgsl", include_str!("../../shaders/pem_filter.wgsl")),
    ("depth_tiles.wgsl", include_str!("../../shaders/depth_tiles.wgsl")),
    ("pem_phong.wgsl", include_str!("../../shaders/pem_phong.wgsl")),
    ("cube_preview.wgsl", include_str!("../../shaders/cube_preview.wgsl")),
    ("ibl_shading.wgsl", include_str!("../../shaders/ibl_shading.wgsl")),
    ("ssao.wgsl", include_str!("../../shaders/ssao.wgsl")),
    ("vsm.wgsl", include_str!("../../shaders/vsm.wgsl")),
    ("vsm_blur.wgsl", include_str!("../../shaders/vsm_blur.wgsl")),
    ("hybrid_occlusion.wgsl", include_str!("../../shaders/hybrid_occlusion.wgsl")),
    ("cuboid.wgsl", include_str!("../../shaders/cuboid.wgsl")),
    ("cuboid_gbuffer.wgsl", include_str!("../../shaders/cuboid_gbuffer.wgsl")),
    ("cuboid_depth.wgsl", include_str!("../../shaders/cuboid_depth.wgsl")),
];

pub fn names() -> impl Iterator<Item = &'static str> {
    EMBEDDED.iter().map(|(n, _)| *n)
}

/// The source of `shaders/NAME` with includes expanded: read from `WERKSTATT_SHADER_DIR` when
/// set (live editing), otherwise the copy embedded at build time.
pub fn source(name: &str) -> anyhow::Result<String> {
    let dir = shader_dir();
    Ok(expand(name, &mut |n| read(dir.as_deref(), n))?.0)
}

/// The text of one file, `shaders/NAME`, without expanding includes: from `dir` if given,
/// else the embedded copy.
pub fn read(dir: Option<&std::path::Path>, name: &str) -> anyhow::Result<String> {
    if let Some(dir) = dir {
        let path = dir.join(name);
        return std::fs::read_to_string(&path).with_context(|| format!("cannot read shader {}", path.display()));
    }
    EMBEDDED
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, s)| s.to_string())
        .with_context(|| format!("no shader named {name} is embedded"))
}

/// `name` with its includes expanded, reading files with `read`; also returns every file
/// the result was made from (`name` first), so a change to any of them can be noticed.
pub fn expand(
    name: &str,
    read: &mut dyn FnMut(&str) -> anyhow::Result<String>,
) -> anyhow::Result<(String, Vec<String>)> {
    let mut files = Vec::new();
    let text = expand_into(name, 0, read, &mut files)?;
    Ok((text, files))
}

fn expand_into(
    name: &str,
    depth: usize,
    read: &mut dyn FnMut(&str) -> anyhow::Result<String>,
    files: &mut Vec<String>,
) -> anyhow::Result<String> {
    if depth > 8 {
        bail!("shader includes nest too deeply at {name} (a cycle?)");
    }
    if !files.iter().any(|f| f == name) {
        files.push(name.to_string());
    }
    let text = read(name)?;
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        match line.trim().strip_prefix("// #include ") {
            Some(inc) => {
                let inc = inc.trim().trim_matches('"');
                out.push_str(
                    &expand_into(inc, depth + 1, read, files).with_context(|| format!("included from {name}"))?,
                );
            }
            None => out.push_str(line),
        }
        out.push('\n');
    }
    Ok(out)
}

/// Where shader sources are read from disk when live editing, if anywhere.
pub fn shader_dir() -> Option<std::path::PathBuf> {
    std::env::var_os("WERKSTATT_SHADER_DIR").map(std::path::PathBuf::from)
}
