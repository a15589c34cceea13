//! The cuboid scene graph (dissertation sections 3.1.1 and 4.1.1, `TECHNIQUES.md` section 1):
//! trilinear transforms of 8 corners, uniform grids of them, their composition, the linear
//! fast path, normals by two methods, and anchors on a deforming mesh.
//!
//! Conventions (see `docs/cuboids.md`):
//! - corner `i` sits at the unit-cube corner `(i & 1, (i >> 1) & 1, (i >> 2) & 1)`, so
//!   `p0 = (0,0,0)`, `p1 = (1,0,0)`, `p2 = (0,1,0)`, ..., `p7 = (1,1,1)` (eq. 3.1);
//! - the coefficient matrix `C` of eq. 3.4 is 3x8 (the text prints "8x3"): its columns are
//!   `c_xyz c_yz c_xz c_xy | c_z c_y c_x c_1` and `v' = C v` with
//!   `v = (xyz, yz, xz, xy, z, y, x, 1)`;
//! - a grid maps its bounding box (the content's box) onto the unit cube, then the unit cube
//!   through `n_x x n_y x n_z` side-by-side cuboids; points outside the box extrapolate the
//!   nearest cell's polynomial.
//!
//! CPU math is in f64 so the composed transforms lose nothing before they reach the GPU's f32.

use std::sync::Arc;

use glam::{DMat3, DMat4, DVec3, Mat4, Vec3};

use crate::mesh::Mesh;

/// The unit-cube position of corner `i` (eq. 3.1's order).
pub fn unit_corner(i: usize) -> DVec3 {
    DVec3::new((i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64)
}

/// The parameter vector of eq. 3.3: `(xyz, yz, xz, xy, z, y, x, 1)`.
pub fn param_vector(p: DVec3) -> [f64; 8] {
    let (x, y, z) = (p.x, p.y, p.z);
    [x * y * z, y * z, x * z, x * y, z, y, x, 1.0]
}

/// One trilinear transform: the images of the unit cube's 8 corners.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cuboid {
    pub corners: [DVec3; 8],
}

/// The 3x8 coefficient matrix of eq. 3.4, stored as its 8 columns
/// `[c_xyz, c_yz, c_xz, c_xy, c_z, c_y, c_x, c_1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coefficients(pub [DVec3; 8]);

impl Coefficients {
    /// `v' = C v` (eq. 3.4).
    pub fn apply(&self, p: DVec3) -> DVec3 {
        let v = param_vector(p);
        self.0.iter().zip(v).fold(DVec3::ZERO, |acc, (c, s)| acc + *c * s)
    }

    /// The largest length among the non-linear columns (the left half of C), relative to the
    /// size of the parallelepiped of the right half: 0 for a linear transform.
    pub fn nonlinearity(&self) -> f64 {
        let left = self.0[..4].iter().map(|c| c.length()).fold(0.0, f64::max);
        let scale = self.0[4..7].iter().map(|c| c.length()).fold(0.0, f64::max);
        left / scale.max(f64::MIN_POSITIVE)
    }

    /// The right half as an affine matrix (unit cube to world), ignoring the left half.
    pub fn affine_part(&self) -> DMat4 {
        let [.., cz, cy, cx, c1] = self.0;
        DMat4::from_cols(cx.extend(0.0), cy.extend(0.0), cz.extend(0.0), c1.extend(1.0))
    }

    /// The Jacobian d(C v)/d(x, y, z) at `p` (columns: derivatives along x, y, z).
    pub fn jacobian(&self, p: DVec3) -> DMat3 {
        let [cxyz, cyz, cxz, cxy, cz, cy, cx, _] = self.0;
        let (x, y, z) = (p.x, p.y, p.z);
        DMat3::from_cols(
            cx + cxy * y + cxz * z + cxyz * y * z,
            cy + cxy * x + cyz * z + cxyz * x * z,
            cz + cxz * x + cyz * y + cxyz * x * y,
        )
    }
}

impl Cuboid {
    /// The identity on the unit cube.
    pub fn unit() -> Cuboid {
        Cuboid { corners: std::array::from_fn(unit_corner) }
    }

    /// The image of the unit cube under an affine map (a parallelepiped).
    pub fn from_affine(m: DMat4) -> Cuboid {
        Cuboid { corners: std::array::from_fn(|i| m.transform_point3(unit_corner(i))) }
    }

    /// Eq. 3.1: trilinear interpolation of the corners at local coordinates `p`.
    pub fn eval_corners(&self, p: DVec3) -> DVec3 {
        let w = |i: usize| {
            let c = unit_corner(i);
            let f = |t: f64, on: f64| if on > 0.5 { t } else { 1.0 - t };
            f(p.x, c.x) * f(p.y, c.y) * f(p.z, c.z)
        };
        (0..8).fold(DVec3::ZERO, |acc, i| acc + self.corners[i] * w(i))
    }

    /// Eq. 3.2: the columns of C.
    pub fn coefficients(&self) -> Coefficients {
        let p = &self.corners;
        Coefficients([
            p[7] - p[6] - p[5] + p[4] - p[3] + p[2] + p[1] - p[0],
            p[6] - p[4] - p[2] + p[0],
            p[5] - p[4] - p[1] + p[0],
            p[3] - p[2] - p[1] + p[0],
            p[4] - p[0],
            p[2] - p[0],
            p[1] - p[0],
            p[0],
        ])
    }

    /// Eq. 3.4 (the polynomial form; equals [`Cuboid::eval_corners`]).
    pub fn eval(&self, p: DVec3) -> DVec3 {
        self.coefficients().apply(p)
    }

    /// The linear fast path: the affine map (unit cube to world) when the left half of C is
    /// zero within `tolerance` (relative to the cuboid's size).
    pub fn as_affine(&self, tolerance: f64) -> Option<DMat4> {
        let c = self.coefficients();
        (c.nonlinearity() <= tolerance).then(|| c.affine_part())
    }
}

/// How normals follow a trilinear transform (Fig. 4.5); both are evaluated at the vertex,
/// since the Jacobian `J` varies with position. The discriminant indexes the drawer's
/// trilinear pipelines (one vertex entry point each, shaders/cuboid/cuboid_gbuffer.wgsl).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum NormalMethod {
    /// Transform the tangent space: `n' = (J t) x (J b) = cof(J) n`, orthogonal to the
    /// deformed surface; the shading shows the cells' C0 seams.
    #[default]
    TangentSpace = 0,
    /// Transform the normal directly as a direction: `n' = J n`; not orthogonal to the
    /// deformed surface in general, but it varies less across cell borders.
    Direct = 1,
}

impl NormalMethod {
    pub fn transform(self, jacobian: DMat3, n: DVec3) -> DVec3 {
        let out = match self {
            // The cofactor matrix is det(J) J^-T; written out it stays finite for singular J.
            NormalMethod::TangentSpace => cofactor(jacobian) * n,
            NormalMethod::Direct => jacobian * n,
        };
        out.normalize_or_zero()
    }
}

/// The cofactor matrix of `m`: maps `a x b` to `(m a) x (m b)`.
pub fn cofactor(m: DMat3) -> DMat3 {
    DMat3::from_cols(m.y_axis.cross(m.z_axis), m.z_axis.cross(m.x_axis), m.x_axis.cross(m.y_axis))
}

/// A uniform grid of cuboids over a bounding box: `(n_x+1)(n_y+1)(n_z+1)` corner positions,
/// trilinear inside each cell. A single cuboid is a grid of one cell. A grid is not changed
/// once built: its fast-path test is made once, on first use ([`CuboidGrid::linear`]).
pub struct CuboidGrid {
    /// The box of the content, mapped onto the unit cube before the cells apply.
    pub box_min: DVec3,
    pub box_max: DVec3,
    /// Cells per axis, each at least 1.
    pub cells: [usize; 3],
    /// Corner positions, x fastest: `x + (n_x+1) (y + (n_y+1) z)`.
    pub corners: Vec<DVec3>,
    /// How normals are transformed when drawn.
    pub normals: NormalMethod,
    /// [`CuboidGrid::linear`]'s answer: a composed grid is asked when it is composed and again
    /// by the drawer, every frame, for each of thousands of objects.
    linear: std::sync::OnceLock<Option<DMat4>>,
}

impl Clone for CuboidGrid {
    fn clone(&self) -> Self {
        CuboidGrid::new(self.box_min, self.box_max, self.cells, self.corners.clone(), self.normals)
            .expect("a grid's own parts are valid")
    }
}

impl std::fmt::Debug for CuboidGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "CuboidGrid {}x{}x{} over {:?}..{:?}",
            self.cells[0],
            self.cells[1],
            self.cells[2],
            self.box_min.to_array(),
            self.box_max.to_array()
        )
    }
}

/// A grid's fast-path tolerance: left half of C over cuboid size (f32 rounding is ~1e-7).
pub const LINEAR_TOLERANCE: f64 = 1e-6;

impl CuboidGrid {
    /// A grid from its parts; errors name what is wrong (for nodes to report).
    pub fn new(
        box_min: DVec3,
        box_max: DVec3,
        cells: [usize; 3],
        corners: Vec<DVec3>,
        normals: NormalMethod,
    ) -> Result<CuboidGrid, String> {
        if cells.contains(&0) {
            return Err(format!("a cuboid grid needs at least one cell per axis, not {cells:?}"));
        }
        let size = box_max - box_min;
        if !size.cmpgt(DVec3::ZERO).all() || !size.is_finite() {
            return Err(format!(
                "the bounding box {:?}..{:?} must have a positive, finite size on every axis",
                box_min.to_array(),
                box_max.to_array()
            ));
        }
        let expected = (cells[0] + 1) * (cells[1] + 1) * (cells[2] + 1);
        if corners.len() != expected {
            return Err(format!("a {cells:?} grid has {expected} corners, not {}", corners.len()));
        }
        if let Some(i) = corners.iter().position(|c| !c.is_finite()) {
            return Err(format!("corner {i} of the cuboid grid is not finite"));
        }
        Ok(CuboidGrid { box_min, box_max, cells, corners, normals, linear: Default::default() })
    }

    /// A grid whose corner at unit-cube position `u` is `f(u)`.
    pub fn from_fn(
        box_min: DVec3,
        box_max: DVec3,
        cells: [usize; 3],
        normals: NormalMethod,
        f: impl Fn(DVec3) -> DVec3,
    ) -> Result<CuboidGrid, String> {
        let lattice = lattice(cells);
        CuboidGrid::new(box_min, box_max, cells, lattice.into_iter().map(f).collect(), normals)
    }

    /// One cuboid over a box.
    pub fn single(box_min: DVec3, box_max: DVec3, cuboid: Cuboid, normals: NormalMethod) -> Result<CuboidGrid, String> {
        CuboidGrid::new(box_min, box_max, [1, 1, 1], cuboid.corners.to_vec(), normals)
    }

    /// The identity over a box, with `cells` cells (the start of a deformation).
    pub fn identity(box_min: DVec3, box_max: DVec3, cells: [usize; 3]) -> Result<CuboidGrid, String> {
        let size = box_max - box_min;
        CuboidGrid::from_fn(box_min, box_max, cells, NormalMethod::default(), |u| box_min + u * size)
    }

    fn index(&self, x: usize, y: usize, z: usize) -> usize {
        x + (self.cells[0] + 1) * (y + (self.cells[1] + 1) * z)
    }

    /// The corner at lattice position `(x, y, z)`.
    pub fn corner(&self, x: usize, y: usize, z: usize) -> DVec3 {
        self.corners[self.index(x, y, z)]
    }

    /// The cuboid of cell `(x, y, z)`.
    pub fn cell(&self, x: usize, y: usize, z: usize) -> Cuboid {
        Cuboid { corners: std::array::from_fn(|i| self.corner(x + (i & 1), y + ((i >> 1) & 1), z + ((i >> 2) & 1))) }
    }

    /// Where `p` lies in the unit cube of the box.
    pub fn to_unit(&self, p: DVec3) -> DVec3 {
        (p - self.box_min) / (self.box_max - self.box_min)
    }

    /// The cell that holds unit position `u` (the nearest one outside) and `u` in it.
    fn locate(&self, u: DVec3) -> ([usize; 3], DVec3) {
        let mut cell = [0; 3];
        let mut local = DVec3::ZERO;
        for a in 0..3 {
            let n = self.cells[a];
            let t = u[a] * n as f64;
            let i = (t.floor().max(0.0) as usize).min(n - 1);
            cell[a] = i;
            local[a] = t - i as f64;
        }
        (cell, local)
    }

    /// The image of `p` (a point in the content's space).
    pub fn eval(&self, p: DVec3) -> DVec3 {
        let ([x, y, z], local) = self.locate(self.to_unit(p));
        self.cell(x, y, z).eval(local)
    }

    /// The Jacobian of the transform at `p`, with respect to `p`.
    pub fn jacobian(&self, p: DVec3) -> DMat3 {
        let ([x, y, z], local) = self.locate(self.to_unit(p));
        let scale = DVec3::new(self.cells[0] as f64, self.cells[1] as f64, self.cells[2] as f64)
            / (self.box_max - self.box_min);
        self.cell(x, y, z).coefficients().jacobian(local) * DMat3::from_diagonal(scale)
    }

    /// The transformed unit normal `n` of a surface through `p`.
    pub fn normal(&self, p: DVec3, n: DVec3) -> DVec3 {
        self.normals.transform(self.jacobian(p), n)
    }

    /// The linear fast path: the affine map of content space when every corner is the same
    /// affine image of the lattice (the left half of C is then zero in every cell). The
    /// dissertation tests grids of one cell only; this also catches larger affine grids.
    pub fn as_affine(&self, tolerance: f64) -> Option<DMat4> {
        let [nx, ny, nz] = self.cells;
        let o = self.corner(0, 0, 0);
        let edges = [self.corner(nx, 0, 0) - o, self.corner(0, ny, 0) - o, self.corner(0, 0, nz) - o];
        let scale = edges.iter().map(|e| e.length()).fold(f64::MIN_POSITIVE, f64::max);
        // Squared distances, lattice steps instead of divisions: the drawer asks this of
        // thousands of composed grids per frame.
        let limit = (tolerance * scale).powi(2);
        let step = [edges[0] / nx as f64, edges[1] / ny as f64, edges[2] / nz as f64];
        let mut corners = self.corners.iter();
        for z in 0..=nz {
            for y in 0..=ny {
                let row = o + step[1] * y as f64 + step[2] * z as f64;
                for x in 0..=nx {
                    if corners.next()?.distance_squared(row + step[0] * x as f64) > limit {
                        return None;
                    }
                }
            }
        }
        let unit_to_world =
            DMat4::from_cols(edges[0].extend(0.0), edges[1].extend(0.0), edges[2].extend(0.0), o.extend(1.0));
        let size = self.box_max - self.box_min;
        let content_to_unit = DMat4::from_scale(1.0 / size) * DMat4::from_translation(-self.box_min);
        Some(unit_to_world * content_to_unit)
    }

    /// The cell that every point of the content-space box `lo..hi` falls in, if it is one:
    /// the cell the vertex stage picks for each of them (the nearest one outside the grid),
    /// so an object inside one cell can draw as that cell's single cuboid.
    pub fn cell_holding(&self, lo: DVec3, hi: DVec3) -> Option<[usize; 3]> {
        let map = self.cell_map();
        let cell = |p: DVec3, axis: usize| {
            // Beyond the grid, the border cell, as in the shader (NaN gives no cell).
            let t = map.transform_point3(p)[axis].floor();
            (!t.is_nan()).then(|| t.clamp(0.0, (self.cells[axis] - 1) as f64) as usize)
        };
        let mut out = [0; 3];
        for (axis, o) in out.iter_mut().enumerate() {
            match (cell(lo, axis), cell(hi, axis)) {
                (Some(a), Some(b)) if a == b && lo[axis] <= hi[axis] => *o = a,
                _ => return None,
            }
        }
        Some(out)
    }

    /// The fast path's answer at [`LINEAR_TOLERANCE`] ([`CuboidGrid::as_affine`]), tested once.
    pub fn linear(&self) -> Option<DMat4> {
        *self.linear.get_or_init(|| self.as_affine(LINEAR_TOLERANCE))
    }

    /// `m` after this grid: exact, since trilinear interpolation commutes with affine maps.
    pub fn then_affine(&self, m: DMat4) -> CuboidGrid {
        let corners = self.corners.iter().map(|c| m.transform_point3(*c)).collect();
        CuboidGrid::new(self.box_min, self.box_max, self.cells, corners, self.normals).expect("same shape")
    }

    /// `outer` after this grid, resampled: this grid's box, at the finer of the two
    /// resolutions per axis (the dissertation propagates the highest resolution), each new
    /// corner the exact image `outer(self(corner))`. Between corners the result only
    /// approximates the composition; its error falls as the grids are refined.
    pub fn then_grid(&self, outer: &CuboidGrid) -> CuboidGrid {
        let cells = std::array::from_fn(|a| self.cells[a].max(outer.cells[a]));
        let size = self.box_max - self.box_min;
        CuboidGrid::from_fn(self.box_min, self.box_max, cells, outer.normals, |u| {
            outer.eval(self.eval(self.box_min + u * size))
        })
        .expect("a resampled grid keeps a valid box")
    }

    /// Appends each cell's coefficient matrix C (eq. 3.4, 3x8, computed in f64 from the
    /// corners) as 6 `vec4<f32>` per cell, cells in corner order (x fastest), to `rows`, the one
    /// storage buffer of all grids a draw uses. Per coordinate r two vec4: (c_xyz, c_yz, c_xz,
    /// c_xy)[r] and (c_z, c_y, c_x, c_1)[r], so shaders/cuboid/cuboid.wgsl evaluates eq. 3.4 as six dot
    /// products after six loads. This replaces the dissertation's 3D texture of positions: the
    /// vertex stage would otherwise load the cell's 8 corners and form C itself for every
    /// vertex (per-lane gathers are most of the trilinear path's cost on lavapipe, and texel
    /// fetches there cost more still), and one buffer for all grids saves a buffer and a bind
    /// group per object and frame.
    pub fn append_cells(&self, rows: &mut Vec<[f32; 4]>) {
        for z in 0..self.cells[2] {
            for y in 0..self.cells[1] {
                for x in 0..self.cells[0] {
                    rows.extend(self.cell_rows(x, y, z));
                }
            }
        }
    }

    /// One cell's rows as [`CuboidGrid::append_cells`] lays them out.
    pub fn cell_rows(&self, x: usize, y: usize, z: usize) -> [[f32; 4]; Self::ROWS_PER_CELL] {
        let c = self.cell(x, y, z).coefficients().0;
        let row = |cols: &[DVec3], r: usize| std::array::from_fn(|k| cols[k][r] as f32);
        std::array::from_fn(|i| row(&c[4 * (i % 2)..][..4], i / 2))
    }

    /// Rows [`CuboidGrid::append_cells`] appends per cell.
    pub const ROWS_PER_CELL: usize = 6;

    /// The map from a point of the grid's content space (its item's model matrix applied)
    /// into the grid's cell coordinates, where cell (i, j, k) spans [i, i+1] x [j, j+1] x
    /// [k, k+1] (shaders/cuboid/cuboid.wgsl finds the cell and eq. 3.4's local point from these).
    /// The item's transform (src/render/draw/compose.rs `ItemVertex`) folds it after the model matrix.
    pub fn cell_map(&self) -> DMat4 {
        DMat4::from_scale(self.cell_scale()) * DMat4::from_translation(-self.box_min)
    }

    /// Cells per unit of content space, per axis: the cell map's scale.
    fn cell_scale(&self) -> DVec3 {
        DVec3::new(self.cells[0] as f64, self.cells[1] as f64, self.cells[2] as f64) / (self.box_max - self.box_min)
    }

    /// The scale the cell map leaves in normals, to fold into the item's normal transform: the
    /// shader's Jacobian J is taken in cell coordinates, so content space sees J S with S the
    /// cell map's scale. The tangent-space method transforms by cof(J S) = cof(J) det(S) S^-1
    /// (det(S) > 0 dropped: normals are normalized), the direct method by J S.
    pub fn normal_scale(&self) -> DVec3 {
        match self.normals {
            NormalMethod::TangentSpace => 1.0 / self.cell_scale(),
            NormalMethod::Direct => self.cell_scale(),
        }
    }
}

/// An analytic bend of the box `lo..hi` (content space): its x extent becomes an arc of
/// `degrees` about an axis parallel to z, curving towards +y, its centre line (y and x at the
/// box centre) keeping its length.
pub fn bend(lo: DVec3, hi: DVec3, degrees: f64) -> impl Fn(DVec3) -> DVec3 {
    let c = (lo + hi) / 2.0;
    let angle = degrees.to_radians();
    let radius = (hi.x - lo.x) / angle;
    move |p: DVec3| {
        if angle.abs() < 1e-12 {
            return p;
        }
        let phi = (p.x - c.x) / radius;
        let r = radius - (p.y - c.y);
        DVec3::new(c.x + r * phi.sin(), c.y + radius - r * phi.cos(), p.z)
    }
}

/// An analytic twist of the box about its vertical (y) centre line: `degrees` from bottom to
/// top, zero at the centre.
pub fn twist(lo: DVec3, hi: DVec3, degrees: f64) -> impl Fn(DVec3) -> DVec3 {
    let c = (lo + hi) / 2.0;
    let rate = degrees.to_radians() / (hi.y - lo.y);
    move |p: DVec3| {
        let a = (p.y - c.y) * rate;
        let (s, co) = a.sin_cos();
        let (dx, dz) = (p.x - c.x, p.z - c.z);
        DVec3::new(c.x + co * dx + s * dz, p.y, c.z - s * dx + co * dz)
    }
}

/// The box wrapped around a torus about the y axis: x runs `degrees` along the major circle
/// of `radius`, y once around the tube of `minor_radius`, z is the distance from the tube's
/// centre circle (the box's mid z on the tube surface).
pub fn torus(lo: DVec3, hi: DVec3, degrees: f64, radius: f64, minor_radius: f64) -> impl Fn(DVec3) -> DVec3 {
    let size = hi - lo;
    move |p: DVec3| {
        let u = (p - lo) / size;
        let theta = u.x * degrees.to_radians();
        let phi = u.y * std::f64::consts::TAU;
        let r = minor_radius + (u.z - 0.5) * size.z;
        let ring = radius + r * phi.cos();
        DVec3::new(ring * theta.cos(), r * phi.sin(), -ring * theta.sin())
    }
}

/// The unit-cube positions of a grid's corners, in corner order.
pub fn lattice(cells: [usize; 3]) -> Vec<DVec3> {
    lattice_points(cells).collect()
}

/// [`lattice`] without collecting it (the fast path test runs per item and frame).
pub fn lattice_points(cells: [usize; 3]) -> impl Iterator<Item = DVec3> {
    let [nx, ny, nz] = cells;
    (0..=nz).flat_map(move |z| {
        (0..=ny).flat_map(move |y| {
            (0..=nx).map(move |x| DVec3::new(x as f64 / nx as f64, y as f64 / ny as f64, z as f64 / nz as f64))
        })
    })
}

/// A draw item's placement: an affine model matrix, then optionally a non-linear grid.
/// Composition rules (outer transform applied to an item's `(model, grid)`):
/// - outer affine `A`, no grid: `model = A model` (the ordinary scene graph);
/// - outer affine `A`, grid `W`: `W' = A o W`, exact (corners mapped by `A`);
/// - outer grid `G`, no grid: the item keeps `model` and gets `G` (exact);
/// - outer grid `G`, grid `W`: `W' = G o W` resampled ([`CuboidGrid::then_grid`]).
///
/// Afterwards the fast path test folds a grid that is affine into the model matrix.
pub fn compose(model: Mat4, grid: Option<&Arc<CuboidGrid>>, outer: &Transform) -> (Mat4, Option<Arc<CuboidGrid>>) {
    let (model, grid) = match (outer, grid) {
        (Transform::Affine(a), None) => (a.as_mat4() * model, None),
        (Transform::Affine(a), Some(w)) => (model, Some(Arc::new(w.then_affine(*a)))),
        (Transform::Grid(g), None) => (model, Some(g.clone())),
        (Transform::Grid(g), Some(w)) => (model, Some(Arc::new(w.then_grid(g)))),
    };
    fast_path(model, grid)
}

/// The linear fast path on a composed placement: a grid that is affine becomes part of the
/// model matrix, so the item draws with the ordinary pipeline.
pub fn fast_path(model: Mat4, grid: Option<Arc<CuboidGrid>>) -> (Mat4, Option<Arc<CuboidGrid>>) {
    match grid {
        Some(g) => match g.linear() {
            Some(a) => (a.as_mat4() * model, None),
            None => (model, Some(g)),
        },
        None => (model, None),
    }
}

/// A transform a grouping node applies to a sub-scene.
#[derive(Clone, Debug)]
pub enum Transform {
    Affine(DMat4),
    Grid(Arc<CuboidGrid>),
}

impl Transform {
    /// A grid, or its affine map where the fast path applies.
    pub fn from_grid(grid: CuboidGrid) -> Transform {
        match grid.linear() {
            Some(a) => Transform::Affine(a),
            None => Transform::Grid(Arc::new(grid)),
        }
    }

    pub fn eval(&self, p: DVec3) -> DVec3 {
        match self {
            Transform::Affine(a) => a.transform_point3(p),
            Transform::Grid(g) => g.eval(p),
        }
    }

    pub fn is_linear(&self) -> bool {
        matches!(self, Transform::Affine(_))
    }

    /// `mesh` with every vertex moved through the transform on the CPU: positions mapped,
    /// tangents by the Jacobian, normals by the grid's method (an affine map's by its
    /// cofactor, the inverse transpose up to scale). UVs, pieces and indices are kept, so the
    /// result is still a Surface that a matrix texture, attachments and anchors can use.
    pub fn deform_mesh(&self, mesh: &Mesh) -> Mesh {
        let mut out = mesh.clone();
        let jacobian = |p: DVec3| match self {
            Transform::Affine(a) => DMat3::from_mat4(*a),
            Transform::Grid(g) => g.jacobian(p),
        };
        for (i, p) in mesh.positions.iter().enumerate() {
            let p = p.as_dvec3();
            let j = jacobian(p);
            out.positions[i] = self.eval(p).as_vec3();
            if let Some(n) = mesh.normals.get(i) {
                out.normals[i] = match self {
                    Transform::Affine(_) => NormalMethod::TangentSpace.transform(j, n.as_dvec3()),
                    Transform::Grid(g) => g.normals.transform(j, n.as_dvec3()),
                }
                .as_vec3();
            }
            for (tangents, t) in
                [(&mut out.tangents_u, mesh.tangents_u.get(i)), (&mut out.tangents_v, mesh.tangents_v.get(i))]
            {
                if let Some(t) = t {
                    tangents[i] = (j * t.as_dvec3()).normalize_or_zero().as_vec3();
                }
            }
        }
        out
    }
}

/// Where a draw item's vertex `p` lands: `grid(model p)`, or `model p` without a grid.
pub fn place_point(model: Mat4, grid: Option<&CuboidGrid>, p: Vec3) -> DVec3 {
    let q = model.as_dmat4().transform_point3(p.as_dvec3());
    grid.map_or(q, |g| g.eval(q))
}

/// An anchor (Fig. 4.6): a point and a tangent point, both barycentric on one triangle of a
/// base mesh, so it follows any animation of that mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Anchor {
    pub triangle: usize,
    pub point: DVec3,
    pub tangent_point: DVec3,
}

/// An anchor's frame on the current mesh: origin, unit tangent, unit bitangent, unit normal
/// (right-handed; the normal is the triangle's face normal, the tangent the direction to the
/// tangent point made orthogonal to it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub origin: DVec3,
    pub tangent: DVec3,
    pub bitangent: DVec3,
    pub normal: DVec3,
}

impl Frame {
    /// The point at `local` (tangent, bitangent, normal) coordinates.
    pub fn point(&self, local: DVec3) -> DVec3 {
        self.origin + self.tangent * local.x + self.bitangent * local.y + self.normal * local.z
    }
}

impl Anchor {
    /// The anchor at UV `uv` with its tangent point `du` further along u, located on the
    /// triangle of `mesh` that contains `uv` in texture space (stable under deformation,
    /// since a deforming mesh keeps its UVs).
    pub fn at_uv(mesh: &Mesh, uv: glam::DVec2, du: f64) -> Result<Anchor, String> {
        Anchor::at_uv_towards(mesh, uv, glam::DVec2::new(du, 0.0))
    }

    /// Like [`Anchor::at_uv`] with the tangent point at `uv + step` (a row of anchors points
    /// its tangents along the row).
    pub fn at_uv_towards(mesh: &Mesh, uv: glam::DVec2, step: glam::DVec2) -> Result<Anchor, String> {
        if mesh.uvs.len() != mesh.positions.len() {
            return Err("the anchor mesh has no texture coordinates".into());
        }
        let tris = mesh.indices.len() / 3;
        for t in 0..tris {
            let [a, b, c] = std::array::from_fn(|k| mesh.uvs[mesh.indices[3 * t + k] as usize].as_dvec2());
            if let Some(w) = barycentric_2d(a, b, c, uv) {
                // The tangent point may leave the triangle: barycentrics extrapolate linearly.
                let tangent_point = barycentric_2d_unclamped(a, b, c, uv + step)
                    .ok_or_else(|| format!("triangle {t} is degenerate in UV space"))?;
                return Ok(Anchor { triangle: t, point: w, tangent_point });
            }
        }
        Err(format!("no triangle of the anchor mesh covers uv ({}, {})", uv.x, uv.y))
    }

    /// The frame on `mesh` now.
    pub fn frame(&self, mesh: &Mesh) -> Result<Frame, String> {
        let t = self.triangle;
        if 3 * t + 2 >= mesh.indices.len() {
            return Err(format!("anchor triangle {t} is not in the mesh ({} triangles)", mesh.indices.len() / 3));
        }
        let p: [DVec3; 3] = std::array::from_fn(|k| mesh.positions[mesh.indices[3 * t + k] as usize].as_dvec3());
        let at = |w: DVec3| p[0] * w.x + p[1] * w.y + p[2] * w.z;
        let origin = at(self.point);
        let normal = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        let towards = at(self.tangent_point) - origin;
        let tangent = (towards - normal * towards.dot(normal)).normalize_or_zero();
        if normal == DVec3::ZERO || tangent == DVec3::ZERO {
            return Err(format!("anchor triangle {t} is degenerate, or its tangent point coincides with its point"));
        }
        Ok(Frame { origin, tangent, bitangent: normal.cross(tangent), normal })
    }
}

fn barycentric_2d_unclamped(a: glam::DVec2, b: glam::DVec2, c: glam::DVec2, p: glam::DVec2) -> Option<DVec3> {
    let det = (b - a).perp_dot(c - a);
    if det.abs() < 1e-14 {
        return None;
    }
    let v = (p - a).perp_dot(c - a) / det;
    let w = (b - a).perp_dot(p - a) / det;
    Some(DVec3::new(1.0 - v - w, v, w))
}

fn barycentric_2d(a: glam::DVec2, b: glam::DVec2, c: glam::DVec2, p: glam::DVec2) -> Option<DVec3> {
    barycentric_2d_unclamped(a, b, c, p).filter(|w| w.min_element() >= -1e-9)
}

crate::choice!(
    /// Which way an anchor grid's top layer is lifted from its anchors.
    pub enum Lift {
        /// Along each anchor's own normal: the grid follows a curved surface, and splays
        /// where the surface curves fast.
        Normal = "normal",
        /// Along the anchors' mean normal: parallel layers, so a tall grid on a surface that
        /// curves (a sole rising at its rim) stays a slab.
        MeanNormal = "mean_normal",
    }
);

/// A 2D array of anchors (`cols` x `rows`, u fastest) driving a grid of
/// `(cols-1) x (rows-1) x 1` cells: corner `(i, j, 0)` is anchor `(i, j)`'s origin, corner
/// `(i, j, 1)` lies `height` along its normal or the mean normal (`lift`). The box maps the
/// content onto it.
#[allow(clippy::too_many_arguments)]
pub fn anchor_grid(
    frames: &[Frame],
    cols: usize,
    rows: usize,
    height: f64,
    lift: Lift,
    box_min: DVec3,
    box_max: DVec3,
    normals: NormalMethod,
) -> Result<CuboidGrid, String> {
    if cols < 2 || rows < 2 || frames.len() != cols * rows {
        return Err(format!(
            "an anchor grid needs at least 2x2 anchors, cols x rows of them; got {cols}x{rows} and {} frames",
            frames.len()
        ));
    }
    let cells = [cols - 1, rows - 1, 1];
    let mean = frames.iter().map(|f| f.normal).sum::<DVec3>().normalize_or_zero();
    if lift == Lift::MeanNormal && mean == DVec3::ZERO {
        return Err("the anchors' normals cancel out: they have no mean normal to lift the grid along".into());
    }
    let mut corners = Vec::with_capacity(cols * rows * 2);
    for z in 0..2 {
        let h = height * z as f64;
        for f in frames {
            corners.push(match lift {
                Lift::Normal => f.point(DVec3::new(0.0, 0.0, h)),
                Lift::MeanNormal => f.origin + mean * h,
            });
        }
    }
    CuboidGrid::new(box_min, box_max, cells, corners, normals)
}

/// A row of anchors (a 1D array) driving a grid of `(n-1) x 1 x 1` cells, for objects along
/// a line on the body (a belt, a zip): corner `(i, j, k)` lies at anchor `i`'s frame
/// coordinates `(0, (j - 1/2) width, k height)`, so the row runs through the middle of the
/// grid's bottom face, across its bitangent.
pub fn anchor_row(
    frames: &[Frame],
    width: f64,
    height: f64,
    box_min: DVec3,
    box_max: DVec3,
    normals: NormalMethod,
) -> Result<CuboidGrid, String> {
    if frames.len() < 2 {
        return Err(format!("a row of anchors needs at least 2 of them, not {}", frames.len()));
    }
    let mut corners = Vec::with_capacity(frames.len() * 4);
    for k in 0..2 {
        for j in 0..2 {
            for f in frames {
                corners.push(f.point(DVec3::new(0.0, (j as f64 - 0.5) * width, height * k as f64)));
            }
        }
    }
    CuboidGrid::new(box_min, box_max, [frames.len() - 1, 1, 1], corners, normals)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cell_holding_a_box_is_the_one_the_vertex_stage_picks_for_all_its_points() {
        let (lo, hi) = (DVec3::new(-1.0, 0.0, 0.0), DVec3::new(2.0, 1.0, 1.0));
        let grid = CuboidGrid::from_fn(lo, hi, [3, 2, 1], NormalMethod::TangentSpace, |u| lo + u * (hi - lo)).unwrap();
        let cell = |a: [f64; 3], b: [f64; 3]| grid.cell_holding(DVec3::from(a), DVec3::from(b));
        assert_eq!(cell([0.1, 0.6, 0.2], [0.9, 0.9, 0.8]), Some([1, 1, 0]));
        // Across the border x = 1 between cells 1 and 2.
        assert_eq!(cell([0.5, 0.6, 0.2], [1.5, 0.9, 0.8]), None);
        // Beyond the grid: the border cells extrapolate.
        assert_eq!(cell([-3.0, -2.0, -5.0], [-1.5, 0.4, 5.0]), Some([0, 0, 0]));
        assert_eq!(cell([1.5, 0.5, 0.2], [9.0, 0.9, 0.8]), Some([2, 1, 0]));
        // An empty box (a mesh without vertices) and NaN have no cell.
        assert_eq!(cell([0.9, 0.6, 0.2], [0.1, 0.9, 0.8]), None);
        assert_eq!(cell([f64::NAN, 0.6, 0.2], [0.9, 0.9, 0.8]), None);
    }

    fn twisted() -> Cuboid {
        let mut c = Cuboid::from_affine(DMat4::from_scale_rotation_translation(
            DVec3::new(2.0, 1.0, 0.5),
            glam::DQuat::from_rotation_y(0.3),
            DVec3::new(1.0, -2.0, 3.0),
        ));
        c.corners[7] += DVec3::new(0.3, 0.2, -0.1);
        c.corners[2] -= DVec3::new(0.1, 0.0, 0.2);
        c
    }

    #[test]
    fn corners_map_to_themselves_and_eq_3_1_equals_eq_3_4() {
        let c = twisted();
        for i in 0..8 {
            assert!(c.eval(unit_corner(i)).distance(c.corners[i]) < 1e-12, "corner {i}");
        }
        for p in [DVec3::new(0.2, 0.7, 0.4), DVec3::new(-0.5, 1.5, 0.5)] {
            assert!(c.eval(p).distance(c.eval_corners(p)) < 1e-12);
        }
    }

    #[test]
    fn the_jacobian_matches_finite_differences() {
        let c = twisted().coefficients();
        let p = DVec3::new(0.3, 0.6, 0.8);
        let j = c.jacobian(p);
        let h = 1e-6;
        for a in 0..3 {
            let mut e = DVec3::ZERO;
            e[a] = h;
            let fd = (c.apply(p + e) - c.apply(p - e)) / (2.0 * h);
            assert!(fd.distance(j.col(a)) < 1e-6, "axis {a}: {fd} vs {}", j.col(a));
        }
    }

    #[test]
    fn tangent_space_normals_stay_orthogonal_and_direct_ones_need_not() {
        let g = CuboidGrid::single(DVec3::ZERO, DVec3::ONE, twisted(), NormalMethod::TangentSpace).unwrap();
        let p = DVec3::new(0.4, 0.5, 0.6);
        let (t, b) = (DVec3::X, DVec3::Y);
        let n = t.cross(b);
        let j = g.jacobian(p);
        let (jt, jb) = (j * t, j * b);
        let tangent = NormalMethod::TangentSpace.transform(j, n);
        assert!(tangent.dot(jt).abs() < 1e-12 && tangent.dot(jb).abs() < 1e-12);
        let direct = NormalMethod::Direct.transform(j, n);
        assert!(direct.dot(jt.normalize()).abs() > 1e-3, "direct normal happens to be orthogonal");
    }

    #[test]
    fn grid_jacobian_includes_the_box_scale() {
        let g = CuboidGrid::identity(DVec3::new(-1.0, 0.0, 2.0), DVec3::new(3.0, 2.0, 3.0), [2, 3, 1]).unwrap();
        assert!(g.jacobian(DVec3::new(0.5, 0.5, 2.5)).abs_diff_eq(DMat3::IDENTITY, 1e-12));
        assert!(g.as_affine(LINEAR_TOLERANCE).unwrap().abs_diff_eq(DMat4::IDENTITY, 1e-12));
    }

    #[test]
    fn bad_grids_are_errors_not_panics() {
        assert!(CuboidGrid::new(DVec3::ZERO, DVec3::ONE, [0, 1, 1], vec![], NormalMethod::Direct).is_err());
        assert!(
            CuboidGrid::new(DVec3::ONE, DVec3::ONE, [1, 1, 1], vec![DVec3::ZERO; 8], NormalMethod::Direct).is_err()
        );
        assert!(
            CuboidGrid::new(DVec3::ZERO, DVec3::ONE, [1, 1, 1], vec![DVec3::ZERO; 7], NormalMethod::Direct).is_err()
        );
        assert!(anchor_grid(&[], 1, 1, 1.0, Lift::Normal, DVec3::ZERO, DVec3::ONE, NormalMethod::Direct).is_err());
    }
}
