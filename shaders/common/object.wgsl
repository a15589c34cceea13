// A drawn object (group 1): its material, and its model matrix for per-pixel PN depth (whose
// fragment stage transforms the triangle's corners), shared by every pass that draws the
// scene (src/render/draw/objects.rs `GpuObject`). All items' objects lie in one storage buffer; a draw binds
// its own items' range (a dynamic offset), so items that share a mesh and maps draw as one
// instanced draw, each entry point picking its instance's object with `use_object`. Vertex
// stages take their transform from the instance-rate `ItemIn` instead (item_in.wgsl).

struct Object {
    model: mat4x4<f32>,
    // Inverse transpose of the model matrix, for normals and tangents.
    normal_matrix: mat4x4<f32>,
    // rgb: linear base colour, a: glossiness.
    base_color: vec4<f32>,
    uv_scale: f32,
    // 1 if a base map is bound.
    has_texture: f32,
    // 1 for detail geometry (attachments), 0 for coarse cloth.
    detail: f32,
    // 1 if a gloss map is bound.
    has_gloss_map: f32,
    // Glossiness where the gloss map is 0.
    gloss_min: f32,
    // The BtfShading material id written to the G-buffer's surface target (0: none).
    btf_id: f32,
    // Pads the object to 256 bytes, the largest storage offset alignment an adapter may ask.
    unused: array<vec4<f32>, 5>,
};

@group(1) @binding(0) var<storage, read> objects: array<Object>;
// The object this invocation draws, set first thing by every entry point.
var<private> object: Object;

fn use_object(index: u32) {
    object = objects[index];
}
@group(1) @binding(1) var base_map: texture_2d<f32>;
@group(1) @binding(2) var base_sampler: sampler;
// Glossiness parameter map (dissertation Fig. 5.23), red channel.
@group(1) @binding(3) var gloss_map: texture_2d<f32>;

