//! The `SettleSurface` node: a garment that already has its shape (a fitted `.mhclo` proxy, an
//! OBJ from another tool) pushed out of its body by quasi-static cloth steps, its shape the rest.

use std::collections::HashMap;
use std::sync::Arc;

use glam::{Vec2, Vec3};

use crate::cloth::{BodyMesh, Cloth, FRAME_DT, PatternMesh, SimParams};
use crate::core::node::prelude::*;
use crate::garment::drape::DrapeParams;
use crate::mesh::Mesh;

pub static SETTLE_SURFACE: NodeSpec = NodeSpec {
    kind: "SettleSurface",
    category: Category::Simulation,
    doc: "Pushes a garment that already has its shape out of the body it was fitted to: a Surface such as Avatar's clothes (a .mhclo proxy fitted to the posed body, which cuts into the body in places) or a MeshFile from another tool. Every frame the surface as it comes in is both the start and the rest shape of the cloth simulator (lengths and angles measured on it; vertices at one position, UV seams, welded), which then takes `steps` quasi-static steps against the body: gravity off, every vertex stopped after each step, so body contacts move the cloth out to the body's thickness (2.5 mm) and its constraints keep its shape, without the motion a dynamic simulation would give it. Nothing carries over between frames: a frame's result depends only on its inputs. Outputs the input's topology, UVs and pieces at the settled positions; the node's counters give the body crossings before and after.",
    inputs: &[
        PortSpec::required("surface", PortType::Surface, "The fitted garment: its shape is the rest shape."),
        PortSpec::required(
            "body",
            PortType::Mesh,
            "The body it was fitted to, posed as it is (Avatar's collision output).",
        ),
    ],
    outputs: &[PortSpec::output("surface", PortType::Surface, "The garment, settled out of the body.")],
    params: &[
        ParamSpec::new(
            "steps",
            ParamKind::Int { default: 4, min: 1, max: 1000 },
            "Quasi-static steps of 1/60 s (20 substeps each) per frame.",
        ),
        ParamSpec::new("self_collision", ParamKind::Bool { default: true }, "Cloth-cloth contacts (slower)."),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(SettleSurfaceNode),
};

/// A surface's vertices welded by position: the cloth's topology and, per surface vertex, its
/// cloth vertex.
pub struct Welded {
    pub mesh: PatternMesh,
    pub positions: Vec<Vec3>,
    /// Per cloth triangle, the surface's UVs at its corners (for [`Cloth::new_shaped`]).
    pub corner_uvs: Vec<[Vec2; 3]>,
    pub cloth_vertex: Vec<u32>,
}

/// Welds `surface`'s vertices that share a position (bit for bit, as a fit computes copies of
/// one vertex alike) and drops triangles that the weld collapses.
pub fn weld(surface: &Mesh) -> Welded {
    let mut index: HashMap<[u32; 3], u32> = HashMap::new();
    let (mut positions, mut uvs, mut pieces) = (Vec::new(), Vec::new(), Vec::new());
    let cloth_vertex: Vec<u32> = surface
        .positions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            *index.entry(p.to_array().map(f32::to_bits)).or_insert_with(|| {
                positions.push(*p);
                uvs.push(surface.uvs[i]);
                pieces.push(surface.piece_ids.get(i).copied().unwrap_or(0));
                positions.len() as u32 - 1
            })
        })
        .collect();
    let (triangles, corner_uvs): (Vec<[u32; 3]>, Vec<[Vec2; 3]>) = surface
        .indices
        .chunks_exact(3)
        .map(|t| ([0, 1, 2].map(|k| cloth_vertex[t[k] as usize]), [0, 1, 2].map(|k| surface.uvs[t[k] as usize])))
        .filter(|([a, b, c], _)| a != b && b != c && a != c)
        .unzip();
    let edges = triangles.iter().flat_map(|t| (0..3).map(move |k| [t[k], t[(k + 1) % 3]]));
    let (sum, count) = edges.fold((0.0f64, 0usize), |(s, n), [a, b]| {
        (s + positions[a as usize].distance(positions[b as usize]) as f64, n + 1)
    });
    let mean_edge_cm = (100.0 * sum / count.max(1) as f64) as f32;
    Welded { mesh: PatternMesh::shaped(triangles, uvs, pieces, mean_edge_cm), positions, corner_uvs, cloth_vertex }
}

struct SettleSurfaceNode;

impl Node for SettleSurfaceNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let surface: Arc<Mesh> = cx.input("surface")?;
        let body: Arc<Mesh> = cx.input("body")?;
        let welded = weld(&surface);
        if welded.mesh.triangles().is_empty() {
            return Err(NodeError::msg("input \"surface\" has no triangles with area"));
        }
        let params =
            SimParams { self_collision: cx.bool("self_collision"), gravity: Vec3::ZERO, ..DrapeParams::default().sim };
        let mut cloth = Cloth::new_shaped(welded.mesh, welded.positions, &welded.corner_uvs, params);
        cloth.set_body(Some(BodyMesh::from_mesh(&body)));
        let before = cloth.body_crossings();
        for _ in 0..cx.int("steps") {
            cloth.step_frame(FRAME_DT);
            cloth.halt();
        }
        if cloth.positions().iter().any(|p| !p.is_finite()) {
            return Err(NodeError::msg("the settle diverged (non-finite positions)"));
        }
        let frame = cloth.surface();
        let at = |i: u32| Vec3::from_array(frame.positions[i as usize]);
        let positions = welded.cloth_vertex.iter().map(|&i| at(i)).collect();
        // A vertex in no triangle with area has no cloth normal: the surface's own stays.
        let normals = (welded.cloth_vertex.iter().zip(&surface.normals))
            .map(|(&i, &own)| Vec3::from_array(frame.normals[i as usize]).try_normalize().unwrap_or(own))
            .collect();
        let mut mesh = Mesh::from_parts(
            positions,
            Some(normals),
            surface.uvs.clone(),
            surface.indices.clone(),
            surface.piece_ids.clone(),
        )
        .map_err(|e| NodeError::msg(format!("the settled garment: {e:#}")))?;
        mesh.seams = surface.seams.clone();
        cx.count("cloth_vertices", cloth.vertex_count());
        cx.count("body_crossings_before", before);
        cx.count("body_crossings", cloth.body_crossings());
        cx.set("surface", Arc::new(mesh));
        Ok(())
    }
}
