// G-buffer pass for items under a non-linear cuboid transform (src/render/draw/): the vertex lands
// at cuboid(cell map * model * p); the fragment stage is the plain G-buffer's.

// #include "gbuffer_common.wgsl"
// #include "item_in.wgsl"
// #include "cuboid.wgsl"

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) view_depth: f32,
    @location(3) @interpolate(flat) object: u32,
    @location(4) world: vec3<f32>,
};

// One instance per item of the draw (`index` picks its object for the fragment stage).
fn deformed_vertex(v: MeshVertexIn, item: ItemIn, d: Deformed, index: u32, direct_normals: bool) -> VertexOut {
    let world = vec4<f32>(d.position, 1.0);
    var out: VertexOut;
    out.clip = frame.view_proj * world;
    // Normalized per vertex: J scales normals differently at each vertex.
    out.normal = normalize(cuboid_normal(d.jacobian, item_normal(item, v.normal), direct_normals));
    out.uv = v.uv;
    out.view_depth = -(frame.view * world).z;
    out.object = index;
    out.world = d.position;
    return out;
}

fn grid_vertex(v: MeshVertexIn, item: ItemIn, index: u32, direct_normals: bool) -> VertexOut {
    let d = cuboid_deform(item_point(item, v.position).xyz, item.grid);
    return deformed_vertex(v, item, d, index, direct_normals);
}

fn single_cuboid_vertex(v: MeshVertexIn, c: CuboidItemIn, index: u32, direct_normals: bool) -> VertexOut {
    let item = cuboid_item(c);
    let rows = CellRows(c.x_left, c.x_right, c.y_left, c.y_right, c.z_left, c.z_right);
    let d = cuboid_eval(item_point(item, v.position).xyz, rows);
    return deformed_vertex(v, item, d, index, direct_normals);
}

// One entry point per normal method (NormalMethod in src/cuboid/mod.rs), for grids and for
// single cuboids.
@vertex
fn vs_tangent_space(v: MeshVertexIn, item: ItemIn, @builtin(instance_index) index: u32) -> VertexOut {
    return grid_vertex(v, item, index, false);
}

@vertex
fn vs_direct(v: MeshVertexIn, item: ItemIn, @builtin(instance_index) index: u32) -> VertexOut {
    return grid_vertex(v, item, index, true);
}

@vertex
fn vs_cuboid_tangent_space(v: MeshVertexIn, item: CuboidItemIn, @builtin(instance_index) index: u32) -> VertexOut {
    return single_cuboid_vertex(v, item, index, false);
}

@vertex
fn vs_cuboid_direct(v: MeshVertexIn, item: CuboidItemIn, @builtin(instance_index) index: u32) -> VertexOut {
    return single_cuboid_vertex(v, item, index, true);
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> GBufferOut {
    use_object(in.object);
    return write_gbuffer(in.world, in.normal, in.uv, in.view_depth, front);
}
