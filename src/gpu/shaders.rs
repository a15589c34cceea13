//! WGSL sources, one file per pass under `shaders/`, grouped in folders by family as `src/` is
//! (`shaders/render/tonemap.wgsl`), embedded in the binary. Passes name a shader by its file
//! name alone (`tonemap.wgsl`), unique across the folders. A line `// #include "name.wgsl"` is
//! replaced by that file, so passes share code (the G-buffer output, the deferred-warping
//! transform) without copies.

use anyhow::{Context as _, bail};

const EMBEDDED: &[(&str, &str)] = &[
    ("common/vertex_in.wgsl", include_str!("../../shaders/common/vertex_in.wgsl")),
    ("common/object.wgsl", include_str!("../../shaders/common/object.wgsl")),
    ("common/gbuffer_common.wgsl", include_str!("../../shaders/common/gbuffer_common.wgsl")),
    ("common/surface.wgsl", include_str!("../../shaders/common/surface.wgsl")),
    ("render/depth.wgsl", include_str!("../../shaders/render/depth.wgsl")),
    ("common/depth_readback.wgsl", include_str!("../../shaders/common/depth_readback.wgsl")),
    ("render/gbuffer.wgsl", include_str!("../../shaders/render/gbuffer.wgsl")),
    ("common/fullscreen.wgsl", include_str!("../../shaders/common/fullscreen.wgsl")),
    ("render/direct_light.wgsl", include_str!("../../shaders/render/direct_light.wgsl")),
    ("render/tonemap.wgsl", include_str!("../../shaders/render/tonemap.wgsl")),
    ("compare/image_difference.wgsl", include_str!("../../shaders/compare/image_difference.wgsl")),
    ("render/display.wgsl", include_str!("../../shaders/render/display.wgsl")),
    ("warp/matrix_out.wgsl", include_str!("../../shaders/warp/matrix_out.wgsl")),
    ("warp/matrix_texture.wgsl", include_str!("../../shaders/warp/matrix_texture.wgsl")),
    ("warp/matrix_filter.wgsl", include_str!("../../shaders/warp/matrix_filter.wgsl")),
    ("warp/piece_map.wgsl", include_str!("../../shaders/warp/piece_map.wgsl")),
    ("warp/warp.wgsl", include_str!("../../shaders/warp/warp.wgsl")),
    ("tessellation/tessellate.wgsl", include_str!("../../shaders/tessellation/tessellate.wgsl")),
    ("tessellation/pn.wgsl", include_str!("../../shaders/tessellation/pn.wgsl")),
    ("tessellation/gbuffer_pn.wgsl", include_str!("../../shaders/tessellation/gbuffer_pn.wgsl")),
    ("tessellation/woven.wgsl", include_str!("../../shaders/tessellation/woven.wgsl")),
    ("tessellation/vertex_out.wgsl", include_str!("../../shaders/tessellation/vertex_out.wgsl")),
    ("common/instance_in.wgsl", include_str!("../../shaders/common/instance_in.wgsl")),
    ("common/item_in.wgsl", include_str!("../../shaders/common/item_in.wgsl")),
    ("warp/attach.wgsl", include_str!("../../shaders/warp/attach.wgsl")),
    ("warp/attach_export.wgsl", include_str!("../../shaders/warp/attach_export.wgsl")),
    ("warp/attach_resolve.wgsl", include_str!("../../shaders/warp/attach_resolve.wgsl")),
    ("ibl/cube.wgsl", include_str!("../../shaders/ibl/cube.wgsl")),
    ("ibl/pem_filter.wgsl", include_str!("../../shaders/ibl/pem_filter.wgsl")),
    ("render/depth_tiles.wgsl", include_str!("../../shaders/render/depth_tiles.wgsl")),
    ("ibl/pem_phong.wgsl", include_str!("../../shaders/ibl/pem_phong.wgsl")),
    ("ibl/cube_preview.wgsl", include_str!("../../shaders/ibl/cube_preview.wgsl")),
    ("ibl/ibl_shading.wgsl", include_str!("../../shaders/ibl/ibl_shading.wgsl")),
    ("ibl/ibl_shading_hw.wgsl", include_str!("../../shaders/ibl/ibl_shading_hw.wgsl")),
    ("ibl/ibl_shading_common.wgsl", include_str!("../../shaders/ibl/ibl_shading_common.wgsl")),
    ("occlusion/ssao.wgsl", include_str!("../../shaders/occlusion/ssao.wgsl")),
    ("occlusion/bounce.wgsl", include_str!("../../shaders/occlusion/bounce.wgsl")),
    ("occlusion/ssr.wgsl", include_str!("../../shaders/occlusion/ssr.wgsl")),
    ("occlusion/screen_space.wgsl", include_str!("../../shaders/occlusion/screen_space.wgsl")),
    ("ibl/vsm.wgsl", include_str!("../../shaders/ibl/vsm.wgsl")),
    ("ibl/vsm_visibility.wgsl", include_str!("../../shaders/ibl/vsm_visibility.wgsl")),
    ("ibl/shadowed_light.wgsl", include_str!("../../shaders/ibl/shadowed_light.wgsl")),
    ("ibl/vsm_blur.wgsl", include_str!("../../shaders/ibl/vsm_blur.wgsl")),
    ("occlusion/hybrid_occlusion.wgsl", include_str!("../../shaders/occlusion/hybrid_occlusion.wgsl")),
    ("cuboid/cuboid.wgsl", include_str!("../../shaders/cuboid/cuboid.wgsl")),
    ("cuboid/cuboid_gbuffer.wgsl", include_str!("../../shaders/cuboid/cuboid_gbuffer.wgsl")),
    ("cuboid/cuboid_depth.wgsl", include_str!("../../shaders/cuboid/cuboid_depth.wgsl")),
    ("btf/btf_shading.wgsl", include_str!("../../shaders/btf/btf_shading.wgsl")),
    ("btf/btf_hem_ids.wgsl", include_str!("../../shaders/btf/btf_hem_ids.wgsl")),
];

/// The file name of every shader (`tonemap.wgsl`).
pub fn names() -> impl Iterator<Item = &'static str> {
    EMBEDDED.iter().map(|(p, _)| file_name(p))
}

/// The path of every shader under `shaders/` (`render/tonemap.wgsl`).
pub fn paths() -> impl Iterator<Item = &'static str> {
    EMBEDDED.iter().map(|(p, _)| *p)
}

/// The path under `shaders/` of the shader named `name` (`tonemap.wgsl` -> `render/tonemap.wgsl`);
/// `name` itself when no embedded shader has that name.
pub fn path(name: &str) -> &str {
    EMBEDDED.iter().map(|(p, _)| *p).find(|p| file_name(p) == name).unwrap_or(name)
}

fn file_name(path: &str) -> &str {
    path.rsplit('/').next().unwrap_or(path)
}

/// The source of the shader named `NAME` with includes expanded: read from `WERKSTATT_SHADER_DIR` when
/// set (live editing), otherwise the copy embedded at build time.
pub fn source(name: &str) -> anyhow::Result<String> {
    let dir = shader_dir();
    Ok(expand(name, &mut |n| read(dir.as_deref(), n))?.0)
}

/// The text of one file, `shaders/FAMILY/NAME`, without expanding includes: from `dir` if given
/// (`dir/FAMILY/NAME`, see [`path`]), else the embedded copy.
pub fn read(dir: Option<&std::path::Path>, name: &str) -> anyhow::Result<String> {
    if let Some(dir) = dir {
        let path = dir.join(path(name));
        return std::fs::read_to_string(&path).with_context(|| format!("cannot read shader {}", path.display()));
    }
    EMBEDDED
        .iter()
        .find(|(p, _)| file_name(p) == name)
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

#[cfg(test)]
mod tests {
    #[test]
    fn shader_file_names_are_unique_across_the_folders() {
        let mut names: Vec<&str> = super::names().collect();
        names.sort();
        let count = names.len();
        names.dedup();
        assert_eq!(names.len(), count, "two shaders share a file name: passes could not tell them apart");
    }
}
