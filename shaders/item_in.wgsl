// An item's vertex-stage transform (src/draw.rs `ItemVertex`): an instance-rate vertex buffer,
// one entry per item, shared by every pass that draws meshes. Lavapipe fetches an
// instance-rate attribute once per batch of vertices, where a storage load indexed by the
// instance is a gather per vertex: with the transforms in the objects' storage buffer, the
// loads were most of the vertex stage's cost.

struct ItemIn {
    // The point transform's columns: the model matrix, or for an item under a non-linear
    // cuboid grid, the model matrix followed by the map into the grid's cell coordinates (cell
    // (i, j, k) spans [i, i+1] x [j, j+1] x [k, k+1]).
    @location(5) transform0: vec4<f32>,
    @location(6) transform1: vec4<f32>,
    @location(7) transform2: vec4<f32>,
    @location(8) transform3: vec4<f32>,
    // The normal transform's columns (xyz): the model's inverse transpose, under a grid
    // folded with the cell map's scale as its normal method needs (src/draw.rs).
    @location(9) normal0: vec4<f32>,
    @location(10) normal1: vec4<f32>,
    @location(11) normal2: vec4<f32>,
    // A non-linear grid: cells per axis (xyz), and its first row of cells counted from the
    // first row its draw binds (w). Zero without a grid.
    @location(12) grid: vec4<u32>,
};

fn item_point(item: ItemIn, p: vec3<f32>) -> vec4<f32> {
    return mat4x4<f32>(item.transform0, item.transform1, item.transform2, item.transform3) * vec4<f32>(p, 1.0);
}

fn item_normal(item: ItemIn, n: vec3<f32>) -> vec3<f32> {
    return mat3x3<f32>(item.normal0.xyz, item.normal1.xyz, item.normal2.xyz) * n;
}
