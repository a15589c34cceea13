// An item's vertex-stage transform (src/render/draw/compose.rs `ItemVertex`): an instance-rate vertex buffer,
// one entry per item, shared by every pass that draws meshes. Lavapipe fetches an
// instance-rate attribute once per batch of vertices, where a storage load indexed by the
// instance is a loop over the vertices of the batch: with the transforms in the objects'
// storage buffer, the loads were most of the vertex stage's cost.

struct ItemIn {
    // The point transform's columns: the model matrix, or for an item under a non-linear
    // cuboid grid, the model matrix followed by the map into the grid's cell coordinates (cell
    // (i, j, k) spans [i, i+1] x [j, j+1] x [k, k+1]).
    @location(5) transform0: vec4<f32>,
    @location(6) transform1: vec4<f32>,
    @location(7) transform2: vec4<f32>,
    @location(8) transform3: vec4<f32>,
    // The normal transform's columns (xyz): the model's inverse transpose, under a grid
    // folded with the cell map's scale as its normal method needs (src/render/draw/).
    @location(9) normal0: vec4<f32>,
    @location(10) normal1: vec4<f32>,
    @location(11) normal2: vec4<f32>,
    // A grid of several cells: cells per axis (xyz), and its first cell in the pass's cell
    // texture (w; cuboid.wgsl). Zero otherwise.
    @location(12) grid: vec4<u32>,
};

// An item under a single cuboid, a grid of one cell (src/render/draw/compose.rs `ItemVertex`): its transform
// maps into the cuboid's unit cube, and its coefficient matrix C (eq. 3.4, rows as in
// cuboid.wgsl) comes as six more instance attributes instead of six texel loads per vertex.
// They take locations 2 and 4 (MeshVertexIn has no tangents) and 12-15: 16 attributes with
// the vertex's three, WebGPU's limit. The first seven are ItemIn's (shader inputs cannot nest
// structs); `cuboid_item` makes an ItemIn of them.
struct CuboidItemIn {
    @location(5) transform0: vec4<f32>,
    @location(6) transform1: vec4<f32>,
    @location(7) transform2: vec4<f32>,
    @location(8) transform3: vec4<f32>,
    @location(9) normal0: vec4<f32>,
    @location(10) normal1: vec4<f32>,
    @location(11) normal2: vec4<f32>,
    @location(2) x_left: vec4<f32>,
    @location(4) x_right: vec4<f32>,
    @location(12) y_left: vec4<f32>,
    @location(13) y_right: vec4<f32>,
    @location(14) z_left: vec4<f32>,
    @location(15) z_right: vec4<f32>,
};

// The transform part of a single cuboid's item (one cell, none of it in the cell texture).
fn cuboid_item(c: CuboidItemIn) -> ItemIn {
    return ItemIn(c.transform0, c.transform1, c.transform2, c.transform3, c.normal0, c.normal1, c.normal2, vec4<u32>(1u, 1u, 1u, 0u));
}

fn item_point(item: ItemIn, p: vec3<f32>) -> vec4<f32> {
    return mat4x4<f32>(item.transform0, item.transform1, item.transform2, item.transform3) * vec4<f32>(p, 1.0);
}

fn item_normal(item: ItemIn, n: vec3<f32>) -> vec3<f32> {
    return mat3x3<f32>(item.normal0.xyz, item.normal1.xyz, item.normal2.xyz) * n;
}
