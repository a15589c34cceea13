//! Export equals render: every kind of item exports the geometry its draw produces, checked
//! against an independent computation per kind; a kind that cannot export says so. A kind
//! defined outside the crate draws and exports through the same trait.

use std::sync::Arc;

use glam::{DVec3, Mat4, Vec3};
use werkstatt::cuboid::{CuboidGrid, NormalMethod, bend, unit_corner};
use werkstatt::gpu::read_back;
use werkstatt::mesh::Mesh;
use werkstatt::nodes::mesh::geometry::{icosahedron, plane};
use werkstatt::render::draw::SceneDrawer;
use werkstatt::render::draw::compose::VertexStage;
use werkstatt::render::draw::export::flatten;
use werkstatt::render::draw::kind::{ExportCx, ExportDevice, Exported, ItemKind, KindDraw, PrepareCx};
use werkstatt::render::draw::kinds::mesh::mesh_draw;
use werkstatt::render::draw::kinds::pn_pixels::PnPixels;
use werkstatt::render::scene::{DrawItem, Material};
use werkstatt::tessellation::{GpuTessellator, Lod, Metric, Mode, Settings, ViewLod};
use werkstatt::warp::gpu::GpuWarper;

use crate::common::{self, gpu};

fn export(items: &[DrawItem], device: ExportDevice) -> anyhow::Result<Mesh> {
    let mut warper = GpuWarper::default();
    flatten(&mut ExportCx { gpu: gpu(), device, warper: &mut warper, placements: false }, items)
}

fn plain(mesh: Mesh, model: Mat4) -> DrawItem {
    DrawItem::plain(Arc::new(mesh), Arc::new(Material::default()), model)
}

fn lod() -> ViewLod {
    ViewLod {
        view_proj: Mat4::IDENTITY,
        eye: Vec3::new(0.0, 0.0, 4.0),
        width: 160.0,
        height: 120.0,
        lod: Lod { near: 1.0, far: 10.0, max_level: 8.0, silhouette: 0.0 },
        metric: Metric::Distance,
        max_edge_px: 20.0,
    }
}

/// The case: a refined icosahedron exported its 12 coarse vertices. Now the read-back
/// and the CPU reference agree within 1e-5, and a uniform level-4 refinement without PN has the
/// welded counts of a level-4 subdivision (V + E (n-1) + F (n-1)(n-2)/2 vertices, F n^2
/// triangles), every vertex on its coarse face; with PN on, the corners stay put and the
/// patches bulge out of the faces.
#[test]
fn a_tessellated_item_exports_its_refined_triangles_alike_on_gpu_and_cpu() {
    let ico = icosahedron(1.0).unwrap();
    let n = 4u32;
    for pn in [false, true] {
        let s = Settings { mode: Mode::Uniform, max_level: n, pn };
        let tess = GpuTessellator::default().run(gpu(), &ico, None, &lod(), &s).unwrap();
        let item = plain(ico.clone(), Mat4::from_translation(Vec3::X)).with_kind(tess);
        let on_gpu = export(std::slice::from_ref(&item), ExportDevice::Gpu).unwrap();
        let on_cpu = export(std::slice::from_ref(&item), ExportDevice::Cpu).unwrap();
        assert_eq!(on_gpu.positions.len(), on_cpu.positions.len(), "pn {pn}: welded vertex counts");
        assert_eq!(on_gpu.indices, on_cpu.indices, "pn {pn}: triangles");
        for (a, b) in on_gpu.positions.iter().zip(&on_cpu.positions) {
            assert!(a.distance(*b) < 1e-5, "pn {pn}: GPU {a} against CPU {b}");
        }
        assert_eq!(on_gpu.triangle_count(), 20 * (n * n) as usize, "pn {pn}");
        if !pn {
            assert_eq!(on_gpu.positions.len(), (12 + 30 * (n - 1) + 20 * (n - 1) * (n - 2) / 2) as usize);
        }
        // Distance of each exported vertex to the nearest coarse face's plane (model applied).
        let off_faces = |p: Vec3| {
            ico.indices
                .chunks_exact(3)
                .map(|t| {
                    let [a, b, c] = [t[0], t[1], t[2]].map(|i| ico.positions[i as usize] + Vec3::X);
                    let normal = (b - a).cross(c - a).normalize();
                    let inside =
                        [(a, b), (b, c), (c, a)].iter().all(|(u, v)| (*v - *u).cross(p - *u).dot(normal) > -1e-4);
                    if inside { (p - a).dot(normal).abs() } else { f32::INFINITY }
                })
                .fold(f32::INFINITY, f32::min)
        };
        let worst = on_gpu.positions.iter().map(|&p| off_faces(p)).fold(0.0f32, f32::max);
        if pn {
            assert!(worst > 0.02, "PN patches should leave the flat faces (furthest {worst})");
        } else {
            assert!(worst < 1e-5, "a flat refinement leaves its faces by {worst}");
        }
        for corner in &ico.positions {
            let p = *corner + Vec3::X;
            assert!(on_gpu.positions.iter().any(|q| q.distance(p) < 1e-5), "corner {p} is not exported");
        }
    }
}

/// Trilinear interpolation of a cell's 8 corners by hand (eq. 3.1), independent of
/// `CuboidGrid::eval`.
fn trilinear(corners: [DVec3; 8], u: DVec3) -> DVec3 {
    (0..8).fold(DVec3::ZERO, |sum, i| {
        let c = unit_corner(i);
        let w = |t: f64, bit: f64| if bit > 0.5 { t } else { 1.0 - t };
        sum + corners[i] * (w(u.x, c.x) * w(u.y, c.y) * w(u.z, c.z))
    })
}

/// The second case: an item under a trilinear cuboid exported undeformed. Now each
/// vertex lands where eq. 3.1 puts it, computed here from the cell's corners: under a single
/// bent cuboid, and under a 4-cell bend grid (each vertex in its own cell).
#[test]
fn an_item_under_a_cuboid_or_grid_exports_deformed_by_eq_3_1() {
    let plate = plane(1.6, 8, 5).unwrap();
    let model = Mat4::from_translation(Vec3::new(0.1, 0.05, 0.0));
    let (lo, hi) = (DVec3::splat(-1.0), DVec3::splat(1.0));
    let bent = |u: DVec3| {
        let p = lo + u * (hi - lo);
        p + DVec3::new(0.0, 0.4 * u.x * u.z + 0.3 * u.x * u.y * u.z, 0.2 * u.x * u.y)
    };
    let single = CuboidGrid::from_fn(lo, hi, [1, 1, 1], NormalMethod::TangentSpace, bent).unwrap();
    let grid = CuboidGrid::from_fn(lo, hi, [4, 1, 2], NormalMethod::Direct, bend(lo, hi, 90.0)).unwrap();
    for g in [single, grid] {
        let item = DrawItem { cuboid: Some(Arc::new(g.clone())), ..plain(plate.clone(), model) };
        let out = export(std::slice::from_ref(&item), ExportDevice::Gpu).unwrap();
        assert_eq!(out.positions.len(), plate.positions.len());
        let mut moved = 0.0f64;
        for (p, q) in plate.positions.iter().zip(&out.positions) {
            let content = model.as_dmat4().transform_point3(p.as_dvec3());
            let cells = DVec3::new(g.cells[0] as f64, g.cells[1] as f64, g.cells[2] as f64);
            let t = (content - lo) / (hi - lo) * cells;
            let cell = t.floor().min(cells - 1.0).max(DVec3::ZERO);
            let [x, y, z] = [cell.x as usize, cell.y as usize, cell.z as usize];
            let corners = std::array::from_fn(|i| {
                let c = unit_corner(i);
                g.corner(x + c.x as usize, y + c.y as usize, z + c.z as usize)
            });
            let expected = trilinear(corners, t - cell);
            assert!((q.as_dvec3() - expected).length() < 1e-5, "{p} exported at {q}, eq. 3.1 gives {expected}");
            moved = moved.max((q.as_dvec3() - content).length());
        }
        assert!(moved > 0.1, "the grid should move the plate (moved at most {moved})");
    }
}

#[test]
fn per_pixel_pn_items_refuse_to_export_instead_of_exporting_the_flat_mesh() {
    let item = plain(icosahedron(1.0).unwrap(), Mat4::IDENTITY).with_kind(PnPixels);
    let err = export(&[item], ExportDevice::Cpu).unwrap_err();
    let text = format!("{err:#}");
    assert!(text.contains("item 0 (per-pixel PN)") && text.contains("no mesh to export"), "{text}");
}

/// A kind made outside the crate: the item's mesh lifted by `0.5` along y, drawn through the
/// mesh pipelines and exported the same way. It draws like a plain item of the lifted mesh and
/// exports that mesh: a new kind needs nothing but its own impl.
struct Lifted(Arc<Mesh>);

impl ItemKind for Lifted {
    fn name(&self) -> &'static str {
        "lifted"
    }
    fn prepare(
        &self,
        cx: &mut PrepareCx<'_, '_>,
        item: &DrawItem,
        stage: VertexStage,
    ) -> anyhow::Result<Option<KindDraw>> {
        mesh_draw(cx, &self.0, &item.material, stage).map(Some)
    }
    fn export(&self, _: &mut ExportCx<'_>, _: &DrawItem) -> anyhow::Result<Exported> {
        Ok(Exported::Local((*self.0).clone()))
    }
}

#[test]
fn a_kind_defined_outside_the_crate_draws_and_exports_through_the_trait() {
    let ball = icosahedron(0.8).unwrap();
    let mut lifted = ball.clone();
    lifted.positions.iter_mut().for_each(|p| p.y += 0.5);
    let lifted =
        Arc::new(Mesh::build(lifted.positions, Some(lifted.uvs), Some(lifted.normals), lifted.indices).unwrap());
    let custom = plain(ball, Mat4::IDENTITY).with_kind(Lifted(lifted.clone()));
    let reference = DrawItem::plain(lifted.clone(), Arc::new(Material::default()), Mat4::IDENTITY);
    let camera = common::camera_toward_origin(Vec3::new(0.0, 0.5, 4.0), 45.0, 20.0);
    let mut drawer = SceneDrawer::default();
    let mut depth = |item: DrawItem| {
        let gb = werkstatt::render::draw::render_gbuffer(gpu(), &mut drawer, &[item], camera, 48, 40).unwrap();
        gpu().submit_checked().unwrap();
        read_back(gpu(), &gb.depth).unwrap().rgba
    };
    let (a, b) = (depth(custom.clone()), depth(reference));
    assert!(a.iter().step_by(4).filter(|d| **d > 0.0).count() > 100, "the custom kind drew nothing");
    assert_eq!(a, b, "the custom kind draws unlike the mesh it stands for");
    let out = export(&[custom], ExportDevice::Cpu).unwrap();
    assert_eq!(out.positions, lifted.positions);
}
