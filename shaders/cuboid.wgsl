// The trilinear (cuboid grid) transform of a draw item (src/cuboid.rs, dissertation eq. 3.4):
// the grid's box and cells are in the object uniform (object.wgsl `grid_*`), its corner
// positions (x fastest, then y, then z) in one storage buffer shared by every grid of the
// draw, from the grid's first corner on: the dissertation's 3D texture of positions, read as
// memory since eq. 3.4 needs the cell's 8 corners anyway (and texel fetches are slow in
// lavapipe's vertex stage).

@group(2) @binding(0) var<storage, read> cuboid_corners: array<vec4<f32>>;

struct Deformed {
    position: vec3<f32>,
    // d(position)/d(input point), for normals.
    jacobian: mat3x3<f32>,
};

fn cuboid_corner(c: vec3<i32>) -> vec3<f32> {
    let nx = i32(object.grid_cells.x) + 1;
    let ny = i32(object.grid_cells.y) + 1;
    return cuboid_corners[i32(object.grid_inv_size.w) + c.x + nx * (c.y + ny * c.z)].xyz;
}

// Maps `p` (after the model matrix) through the grid: into the box's unit cube, into its
// cell (the nearest one outside the box), then eq. 3.4 with the cell's coefficient matrix.
fn cuboid_deform(p: vec3<f32>) -> Deformed {
    let n = object.grid_cells.xyz;
    let t = (p - object.grid_min.xyz) * object.grid_inv_size.xyz * n;
    let cell = clamp(floor(t), vec3<f32>(0.0), n - 1.0);
    let l = t - cell;
    let i = vec3<i32>(cell);
    let p0 = cuboid_corner(i);
    let p1 = cuboid_corner(i + vec3<i32>(1, 0, 0));
    let p2 = cuboid_corner(i + vec3<i32>(0, 1, 0));
    let p3 = cuboid_corner(i + vec3<i32>(1, 1, 0));
    let p4 = cuboid_corner(i + vec3<i32>(0, 0, 1));
    let p5 = cuboid_corner(i + vec3<i32>(1, 0, 1));
    let p6 = cuboid_corner(i + vec3<i32>(0, 1, 1));
    let p7 = cuboid_corner(i + vec3<i32>(1, 1, 1));
    // Eq. 3.2: the columns of C (3x8), its non-linear left half and affine right half.
    let c_xyz = p7 - p6 - p5 + p4 - p3 + p2 + p1 - p0;
    let c_yz = p6 - p4 - p2 + p0;
    let c_xz = p5 - p4 - p1 + p0;
    let c_xy = p3 - p2 - p1 + p0;
    let c_z = p4 - p0;
    let c_y = p2 - p0;
    let c_x = p1 - p0;
    let left = mat4x3<f32>(c_xyz, c_yz, c_xz, c_xy);
    let right = mat4x3<f32>(c_z, c_y, c_x, p0);
    let x = l.x;
    let y = l.y;
    let z = l.z;
    var out: Deformed;
    // Eq. 3.4: v' = C v, v = (xyz, yz, xz, xy, z, y, x, 1).
    out.position = left * vec4<f32>(x * y * z, y * z, x * z, x * y) + right * vec4<f32>(z, y, x, 1.0);
    let dx = c_x + c_xy * y + c_xz * z + c_xyz * y * z;
    let dy = c_y + c_xy * x + c_yz * z + c_xyz * x * z;
    let dz = c_z + c_xz * x + c_yz * y + c_xyz * x * y;
    let s = n * object.grid_inv_size.xyz;
    out.jacobian = mat3x3<f32>(dx * s.x, dy * s.y, dz * s.z);
    return out;
}

// Fig. 4.5's two methods: the tangent space (cofactor of J: orthogonal to the deformed
// surface), or the normal directly (J n: smoother across cell borders). A blend, not a
// branch: lavapipe recompiles a shader for every value of a uniform that steers control flow.
fn cuboid_normal(j: mat3x3<f32>, n: vec3<f32>) -> vec3<f32> {
    let cof = mat3x3<f32>(cross(j[1], j[2]), cross(j[2], j[0]), cross(j[0], j[1]));
    return mix(cof * n, j * n, object.grid_min.w);
}
