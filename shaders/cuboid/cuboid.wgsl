// The trilinear (cuboid grid) transform of a draw item (src/cuboid/mod.rs, dissertation eq. 3.4):
// the item's transform (item_in.wgsl) takes a vertex into the grid's cell coordinates; its
// cells' coefficient matrices C (3x8, six texels per cell: per coordinate the left and the
// right half, cells x fastest, then y, then z; CuboidGrid::append_cells) lie in one texture
// shared by every grid of the pass (binding 4 of the object group; the item's `grid.w` is
// its grid's first cell there; src/render/draw/compose.rs `CellTextures`): six loads per vertex instead of
// the cell's eight corners, and C is formed once per cell on the CPU, not once per vertex.

@group(1) @binding(4) var cuboid_cells: texture_2d<f32>;

// Cells per texel row of `cuboid_cells` (src/render/draw/compose.rs `CELLS_PER_ROW`).
const CELLS_PER_ROW: u32 = 1024u;

// A cell's coefficient matrix C by rows: left half (c_xyz, c_yz, c_xz, c_xy) and right half
// (c_z, c_y, c_x, c_1) of each coordinate.
struct CellRows {
    x_left: vec4<f32>,
    x_right: vec4<f32>,
    y_left: vec4<f32>,
    y_right: vec4<f32>,
    z_left: vec4<f32>,
    z_right: vec4<f32>,
};

// Row `k` of cell `cell`'s coefficient matrix.
fn cell_row(cell: u32, k: u32) -> vec4<f32> {
    return textureLoad(cuboid_cells, vec2<u32>(6u * (cell % CELLS_PER_ROW) + k, cell / CELLS_PER_ROW), 0);
}

fn cell_rows(cell: u32) -> CellRows {
    return CellRows(cell_row(cell, 0u), cell_row(cell, 1u), cell_row(cell, 2u), cell_row(cell, 3u), cell_row(cell, 4u), cell_row(cell, 5u));
}

struct Deformed {
    position: vec3<f32>,
    // d(position)/d(cell coordinates), for normals (the item's normal transform holds the
    // cell map's scale).
    jacobian: mat3x3<f32>,
};

// Maps `t` (cell coordinates of `grid`: cells per axis in xyz, first cell in the cell texture
// in w) through its cell (the nearest one outside the grid).
fn cuboid_deform(t: vec3<f32>, grid: vec4<u32>) -> Deformed {
    let n = vec3<f32>(grid.xyz);
    let cell = clamp(floor(t), vec3<f32>(0.0), n - 1.0);
    let index = grid.w + u32(cell.x + n.x * (cell.y + n.y * cell.z));
    return cuboid_eval(t - cell, cell_rows(index));
}

// Eq. 3.4 at `l`, the point in the cell's unit cube (outside it, the cell's extrapolation),
// and its Jacobian, from the columns of C = [c_xyz c_yz c_xz c_xy | c_z c_y c_x c_1].
fn cuboid_eval(l: vec3<f32>, c: CellRows) -> Deformed {
    let c_xyz = vec3<f32>(c.x_left.x, c.y_left.x, c.z_left.x);
    let c_yz = vec3<f32>(c.x_left.y, c.y_left.y, c.z_left.y);
    let c_xz = vec3<f32>(c.x_left.z, c.y_left.z, c.z_left.z);
    let c_xy = vec3<f32>(c.x_left.w, c.y_left.w, c.z_left.w);
    let c_z = vec3<f32>(c.x_right.x, c.y_right.x, c.z_right.x);
    let c_y = vec3<f32>(c.x_right.y, c.y_right.y, c.z_right.y);
    let c_x = vec3<f32>(c.x_right.z, c.y_right.z, c.z_right.z);
    let c_1 = vec3<f32>(c.x_right.w, c.y_right.w, c.z_right.w);
    let x = l.x;
    let y = l.y;
    let z = l.z;
    var out: Deformed;
    // v' = C v, v = (xyz, yz, xz, xy, z, y, x, 1).
    out.position = c_xyz * (x * y * z) + c_yz * (y * z) + c_xz * (x * z) + c_xy * (x * y) + c_z * z + c_y * y + c_x * x + c_1;
    // Its derivatives along x, y, z (no products with the zeros of dv/dx, which the shader
    // compiler may not drop).
    let dx = c_xyz * (y * z) + c_xz * z + c_xy * y + c_x;
    let dy = c_xyz * (x * z) + c_yz * z + c_xy * x + c_y;
    let dz = c_xyz * (x * y) + c_yz * y + c_xz * x + c_z;
    out.jacobian = mat3x3<f32>(dx, dy, dz);
    return out;
}

// Fig. 4.5's two methods: the tangent space (cofactor of J: orthogonal to the deformed
// surface), or the normal directly (J n: smoother across cell borders). `direct` is a
// constant at each call site (one vertex entry point per method, cuboid_gbuffer.wgsl), so the
// compiler keeps one of the two: a branch on a uniform would make lavapipe recompile the
// shader for every value, and a blend of both costs the other's arithmetic per vertex.
fn cuboid_normal(j: mat3x3<f32>, n: vec3<f32>, direct: bool) -> vec3<f32> {
    if direct {
        return j * n;
    }
    return mat3x3<f32>(cross(j[1], j[2]), cross(j[2], j[0]), cross(j[0], j[1])) * n;
}
