// Copies a depth texture into a buffer of f32, row-major (src/gpu/readback.rs): OpenGL ES
// cannot copy depth textures to buffers, and this path is the same on every backend.

// Bound as an unfilterable float texture: naga's GLSL output cannot textureLoad a depth texture.
@group(0) @binding(0) var depth: texture_2d<f32>;
@group(0) @binding(1) var<storage, read_write> texels: array<f32>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(depth);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    texels[id.y * size.x + id.x] = textureLoad(depth, vec2<i32>(id.xy), 0).r;
}
