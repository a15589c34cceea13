//! WGSL sources, one file per pass under `shaders/`, embedded in the binary.

use anyhow::Context as _;

const EMBEDDED: &[(&str, &str)] = &[
    ("gbuffer.wgsl", include_str!("../shaders/gbuffer.wgsl")),
    ("direct_light.wgsl", include_str!("../shaders/direct_light.wgsl")),
    ("tonemap.wgsl", include_str!("../shaders/tonemap.wgsl")),
];

pub fn names() -> impl Iterator<Item = &'static str> {
    EMBEDDED.iter().map(|(n, _)| *n)
}

/// The source of `shaders/NAME`: from `WERKSTATT_SHADER_DIR` when set (live editing),
/// otherwise the copy embedded at build time.
pub fn source(name: &str) -> anyhow::Result<String> {
    if let Some(dir) = crate::gpu::shader_dir() {
        let path = dir.join(name);
        return std::fs::read_to_string(&path).with_context(|| format!("cannot read shader {}", path.display()));
    }
    EMBEDDED
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, s)| s.to_string())
        .with_context(|| format!("no shader named {name} is embedded"))
}
