//! The graph canvas: the document shown with egui-snarl. Snarl holds a view of the graph
//! (one snarl node per document node, its value the node id) that is re-synced whenever the
//! document changes; everything the user does on the canvas becomes an [`Action`] that the
//! app applies to the [`EditorState`](super::state::EditorState), so the document stays the
//! one source of truth and every edit is undoable.

use std::cell::RefCell;
use std::collections::{BTreeSet, HashMap};
use std::rc::Rc;

use egui::emath::TSTransform;
use egui::{Color32, Id, Pos2, Rect, RichText, Sense, Stroke, Ui, pos2, vec2};
use egui_snarl::ui::{
    AnyPins, BackgroundPattern, NodeLayout, PinInfo, PinPlacement, PinShape, PinWireInfo, SelectionStyle, SnarlPin,
    SnarlStyle, SnarlViewer, SnarlWidget,
};
use egui_snarl::{InPin, InPinId, NodeId, OutPin, OutPinId, Snarl};

use super::document::compatible_kinds;
use super::live::{Live, NodeState};
use crate::core::graph::{Graph, Link, PortRef};
use crate::core::node::{Category, NodeSpec};
use crate::core::port::PortType;
use crate::core::spec;

/// The colour of a port type, shared by pins, wires and the inspector.
pub fn port_color(ty: PortType) -> Color32 {
    let [r, g, b] = ty.color();
    Color32::from_rgb(r, g, b)
}

pub const ERROR_COLOR: Color32 = Color32::from_rgb(255, 110, 100);
pub const PENDING_COLOR: Color32 = Color32::from_rgb(240, 190, 80);
const SELECT_COLOR: Color32 = Color32::from_rgb(255, 200, 60);

/// What the user asked for on the canvas, applied after drawing.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    Connect(PortRef, PortRef),
    RemoveLink(Link),
    DisconnectInput(PortRef),
    DisconnectOutput(PortRef),
    Add {
        kind: &'static str,
        pos: [f32; 2],
    },
    /// A wire dropped on empty space: add `kind` and connect its `new_port` to `port`.
    AddConnected {
        kind: &'static str,
        pos: [f32; 2],
        port: PortRef,
        from_output: bool,
        new_port: &'static str,
    },
    Inspect(Option<PortRef>),
    SelectOnly(String),
    SetSelection(BTreeSet<String>),
    Move(Vec<(String, [f32; 2])>),
    InsertOnLink(String, Link),
    Delete,
    Duplicate,
    Copy,
}

/// Where pins were drawn (graph space), keyed by node id, input or output, and index.
type PinRects = HashMap<(String, bool, usize), Pos2>;

/// A pin drawn as its type's coloured shape, recording where it was drawn.
struct TypedPin {
    info: PinInfo,
    key: (String, bool, usize),
    sink: Rc<RefCell<PinRects>>,
}

impl SnarlPin for TypedPin {
    fn draw(self, snarl_style: &SnarlStyle, style: &egui::Style, rect: Rect, painter: &egui::Painter) -> PinWireInfo {
        self.sink.borrow_mut().insert(self.key, rect.center());
        self.info.draw(snarl_style, style, rect, painter)
    }
}

/// The smallest zoom framing picks: node titles stay readable (13-point text at 0.7 is about
/// 9 pixels), and a larger graph is panned instead of shrunk. Ctrl+scroll zooms out further.
pub const MIN_FIT_ZOOM: f32 = 0.7;

pub struct Canvas {
    snarl: Snarl<String>,
    ids: HashMap<String, NodeId>,
    synced: u64,
    pins: Rc<RefCell<PinRects>>,
    node_rects: HashMap<String, Rect>,
    /// Width of each node's header content, which the node must be at least as wide as.
    header_widths: HashMap<String, f32>,
    /// Each node's spec, looked up once per document revision.
    specs: HashMap<String, &'static NodeSpec>,
    snarl_selection: Vec<NodeId>,
    to_global: TSTransform,
    canvas_rect: Rect,
    pub show_timings: bool,
    pub search: String,
    id: Id,
    /// Frames drawn since the view was reset; the first frames measure the nodes.
    frames: u32,
    fit_pending: bool,
    /// The wire a dragged node would be inserted into (graph space), drawn under the nodes.
    insert_hint: Option<Vec<Pos2>>,
}

impl Default for Canvas {
    fn default() -> Self {
        Canvas::new()
    }
}

impl Canvas {
    pub fn new() -> Self {
        Canvas {
            snarl: Snarl::new(),
            ids: HashMap::new(),
            synced: 0,
            pins: Rc::default(),
            node_rects: HashMap::new(),
            header_widths: HashMap::new(),
            specs: HashMap::new(),
            snarl_selection: Vec::new(),
            to_global: TSTransform::IDENTITY,
            canvas_rect: Rect::NOTHING,
            show_timings: false,
            search: String::new(),
            id: Id::new("werkstatt-canvas"),
            frames: 0,
            fit_pending: true,
            insert_hint: None,
        }
    }

    /// Brings snarl's view in line with the document (nodes, positions, wires). Snarl node
    /// ids of surviving nodes are kept, so their layout and selection survive edits.
    pub fn sync(&mut self, graph: &Graph, revision: u64) {
        if self.synced == revision {
            return;
        }
        self.synced = revision;
        let old_specs = std::mem::take(&mut self.specs);
        self.specs = graph.nodes.iter().filter_map(|(id, n)| Some((id.clone(), spec::find(&n.kind)?))).collect();
        // A node whose kind changed (a reload from disk) gets a fresh snarl node: its pin
        // rows differ.
        for (id, spec) in &old_specs {
            if self.specs.get(id).is_some_and(|s| s.kind != spec.kind)
                && let Some(n) = self.ids.remove(id)
            {
                self.snarl.remove_node(n);
            }
        }
        let gone: Vec<String> = self.ids.keys().filter(|id| !graph.nodes.contains_key(*id)).cloned().collect();
        for id in gone {
            if let Some(n) = self.ids.remove(&id) {
                self.snarl.remove_node(n);
            }
            self.node_rects.remove(&id);
        }
        for (id, doc) in &graph.nodes {
            let pos = canvas_pos(doc.pos);
            match self.ids.get(id) {
                Some(&n) => {
                    if let Some(info) = self.snarl.get_node_info_mut(n) {
                        info.pos = pos;
                    }
                }
                None => {
                    let n = self.snarl.insert_node(pos, id.clone());
                    self.ids.insert(id.clone(), n);
                }
            }
        }
        let mut wanted = std::collections::HashSet::new();
        for l in &graph.links {
            let (Some(&from), Some(&to)) = (self.ids.get(&l.from.node), self.ids.get(&l.to.node)) else { continue };
            let out = spec_of(graph, &l.from.node).and_then(|s| s.output(&l.from.port)).map(|(i, _)| i);
            let inp = spec_of(graph, &l.to.node).and_then(|s| s.input(&l.to.port)).map(|(i, _)| i);
            if let (Some(output), Some(input)) = (out, inp) {
                wanted.insert((OutPinId { node: from, output }, InPinId { node: to, input }));
            }
        }
        let current: Vec<(OutPinId, InPinId)> = self.snarl.wires().collect();
        for (o, i) in current {
            if !wanted.contains(&(o, i)) {
                self.snarl.disconnect(o, i);
            }
        }
        for (o, i) in wanted {
            self.snarl.connect(o, i);
        }
    }

    /// Forgets the view (a new document was opened).
    pub fn reset(&mut self) {
        *self = Canvas { show_timings: self.show_timings, ..Canvas::new() };
    }

    /// Whether a dragged node is over a wire it would be inserted into.
    pub fn shows_insert_hint(&self) -> bool {
        self.insert_hint.is_some()
    }

    /// Frames all nodes in the view (once their sizes are known), at a zoom no smaller than
    /// [`MIN_FIT_ZOOM`].
    pub fn request_fit(&mut self) {
        self.fit_pending = true;
    }

    /// The view transform that shows every node, if the nodes have been measured.
    fn fit_transform(&self, graph: &Graph) -> Option<TSTransform> {
        if !self.canvas_rect.is_finite() || self.canvas_rect.width() < 10.0 || self.frames < 5 {
            return None;
        }
        let mut bb = Rect::NOTHING;
        for id in graph.nodes.keys() {
            bb = bb.union(*self.node_rects.get(id)?);
        }
        if !bb.is_finite() {
            return Some(TSTransform::new(self.canvas_rect.center().to_vec2(), 1.0));
        }
        let bb = bb.expand(30.0);
        let area = self.canvas_rect.shrink(10.0);
        let s = (area.width() / bb.width()).min(area.height() / bb.height()).clamp(MIN_FIT_ZOOM, 1.0);
        // Centred along an axis where the graph fits; else its start (top, left) is shown and
        // the user pans to the rest.
        let place = |lo: f32, hi: f32, a_lo: f32, a_hi: f32| {
            if (hi - lo) * s <= a_hi - a_lo { (a_lo + a_hi) * 0.5 - (lo + hi) * 0.5 * s } else { a_lo - lo * s }
        };
        let t = egui::vec2(
            place(bb.min.x, bb.max.x, area.min.x, area.max.x),
            place(bb.min.y, bb.max.y, area.min.y, area.max.y),
        );
        Some(TSTransform::new(t, s))
    }

    /// A point in graph space for new nodes: `screen` if it is on the canvas, else the
    /// middle of the visible canvas.
    pub fn graph_pos(&self, screen: Option<Pos2>) -> [f32; 2] {
        let p = match screen {
            Some(p) if self.canvas_rect.contains(p) => p,
            _ if self.canvas_rect.is_finite() => self.canvas_rect.center(),
            _ => Pos2::ZERO,
        };
        let g = self.to_global.inverse() * p;
        [g.x.round(), g.y.round()]
    }

    /// A rectangle on the canvas (in graph space, as widgets inside nodes report it) on screen.
    pub fn to_screen(&self, graph_rect: Rect) -> Rect {
        self.to_global * graph_rect
    }

    /// A spot for a new node near `at` (graph space) that no node covers.
    pub fn free_spot(&self, at: [f32; 2]) -> [f32; 2] {
        let mut p = pos2(at[0], at[1]);
        for _ in 0..60 {
            if !self.node_rects.values().any(|r| r.expand(12.0).contains(p)) {
                break;
            }
            p.y += 40.0;
        }
        [p.x, p.y]
    }

    /// The screen rectangle of a node as drawn last frame, if visible.
    pub fn node_screen_rect(&self, id: &str) -> Option<Rect> {
        self.node_rects.get(id).map(|r| self.to_global * *r)
    }

    /// The screen position of a pin as drawn last frame.
    pub fn pin_screen_pos(&self, port: &PortRef, graph: &Graph, input: bool) -> Option<Pos2> {
        let spec = spec_of(graph, &port.node)?;
        let index = if input { spec.input(&port.port)?.0 } else { spec.output(&port.port)?.0 };
        self.pins.borrow().get(&(port.node.clone(), input, index)).map(|p| self.to_global * *p)
    }

    /// Draws the canvas and returns what the user did.
    pub fn show(
        &mut self,
        ui: &mut Ui,
        graph: &Graph,
        live: &Live,
        selection: &BTreeSet<String>,
        inspected: Option<&PortRef>,
    ) -> Vec<Action> {
        self.pins.borrow_mut().clear();
        self.frames += 1;
        let fit_to = if self.fit_pending { self.fit_transform(graph) } else { None };
        if fit_to.is_some() {
            self.fit_pending = false;
        }
        let style = SnarlStyle {
            node_layout: Some(NodeLayout::coil()),
            pin_placement: Some(PinPlacement::Edge),
            pin_size: Some(9.0),
            wire_width: Some(2.0),
            collapsible: Some(false),
            bg_pattern: Some(BackgroundPattern::grid(vec2(40.0, 40.0), 0.0)),
            select_style: Some(SelectionStyle {
                margin: egui::Margin::same(4),
                rounding: egui::CornerRadius::same(6),
                fill: Color32::TRANSPARENT,
                stroke: Stroke::NONE,
            }),
            max_scale: Some(2.0),
            min_scale: Some(0.1),
            ..SnarlStyle::new()
        };
        let mut viewer = Viewer {
            graph,
            live,
            selection,
            inspected,
            show_timings: self.show_timings,
            actions: Vec::new(),
            pins: self.pins.clone(),
            node_rects: &mut self.node_rects,
            header_widths: &mut self.header_widths,
            specs: &self.specs,
            states: graph.nodes.keys().map(|id| (id.clone(), live.state(id))).collect(),
            search: &mut self.search,
            to_global: self.to_global,
            fit_to,
            insert_hint: self.insert_hint.as_deref(),
            pressed_node: None,
        };
        // Labels must not take drags (text selection) from the nodes they sit on.
        ui.style_mut().interaction.selectable_labels = false;
        let canvas_rect = ui.available_rect_before_wrap();
        let response = SnarlWidget::new().id(self.id).style(style).show(&mut self.snarl, &mut viewer, ui);
        self.to_global = viewer.to_global;
        self.canvas_rect = canvas_rect;
        let pressed_node = viewer.pressed_node.take();
        let mut actions = std::mem::take(&mut viewer.actions);

        let (modifiers, pointer_down) = ui.input(|i| (i.modifiers, i.pointer.any_down()));
        // Selection: snarl's own (shift-click, shift-drag rectangle) when it changes; a plain
        // press on a node selects it; a click on empty canvas clears.
        let snarl_sel = egui_snarl::ui::get_selected_nodes(self.id, ui.ctx());
        if snarl_sel != self.snarl_selection {
            // Apply what changed in snarl's selection to ours, which clicks also change.
            let mut ids = selection.clone();
            let id_of = |n: &NodeId| self.snarl.get_node(*n).cloned();
            for n in self.snarl_selection.iter().filter(|n| !snarl_sel.contains(n)) {
                if let Some(id) = id_of(n) {
                    ids.remove(&id);
                }
            }
            ids.extend(snarl_sel.iter().filter(|n| !self.snarl_selection.contains(n)).filter_map(id_of));
            self.snarl_selection = snarl_sel;
            actions.push(Action::SetSelection(ids));
        } else if let Some(id) = pressed_node {
            if !modifiers.shift && !modifiers.command && !selection.contains(&id) {
                actions.push(Action::SelectOnly(id));
            }
        } else if response.clicked() && !modifiers.shift && !modifiers.command {
            actions.push(Action::SetSelection(BTreeSet::new()));
        }

        // Moves are written to the document when the drag ends (one undo step).
        let moves: Vec<(String, [f32; 2])> = self
            .snarl
            .nodes_pos_ids()
            .filter_map(|(_, pos, id)| {
                let doc = graph.nodes.get(id)?;
                let moved = canvas_pos(doc.pos).distance(pos) > 0.5;
                moved.then(|| (id.clone(), [pos.x, pos.y]))
            })
            .collect();
        self.insert_hint = None;
        if pointer_down {
            // While a free node is dragged over a wire, show (next frame, under the nodes)
            // that dropping it inserts it there.
            if let [(id, _)] = moves.as_slice()
                && let Some(link) = self.link_under(graph, id)
            {
                self.insert_hint = self.wire_points(graph, &link);
                ui.ctx().request_repaint();
            }
        } else {
            if let [(id, _)] = moves.as_slice()
                && let Some(link) = self.link_under(graph, id)
            {
                actions.push(Action::Move(moves.clone()));
                actions.push(Action::InsertOnLink(id.clone(), link));
            } else if !moves.is_empty() {
                actions.push(Action::Move(moves));
            }
        }
        actions
    }

    /// Points along the wire of `link` (graph space), as last drawn.
    fn wire_points(&self, graph: &Graph, link: &Link) -> Option<Vec<Pos2>> {
        let pins = self.pins.borrow();
        let pin = |port: &PortRef, input: bool| {
            let spec = spec_of(graph, &port.node)?;
            let index = if input { spec.input(&port.port)?.0 } else { spec.output(&port.port)?.0 };
            pins.get(&(port.node.clone(), input, index)).copied()
        };
        let (a, b) = (pin(&link.from, false)?, pin(&link.to, true)?);
        let d = ((b.x - a.x).abs() * 0.5).max(40.0);
        let (c1, c2) = (a + vec2(d, 0.0), b - vec2(d, 0.0));
        Some((0..=32).map(|i| bezier(a, c1, c2, b, i as f32 / 32.0)).collect())
    }

    /// A link whose wire passes under node `id`, if the node has no links yet: dropping a
    /// free node onto a wire inserts it there.
    fn link_under(&self, graph: &Graph, id: &str) -> Option<Link> {
        if graph.links.iter().any(|l| l.from.node == id || l.to.node == id) {
            return None;
        }
        let rect = self.node_rects.get(id)?.shrink(4.0);
        graph
            .links
            .iter()
            .filter_map(|l| {
                let hits = self.wire_points(graph, l)?.into_iter().filter(|p| rect.contains(*p)).count();
                (hits > 0).then(|| (hits, l.clone()))
            })
            .max_by_key(|(hits, _)| *hits)
            .map(|(_, l)| l)
    }
}

/// Where a document position goes on the canvas: a file may hold any number, the canvas
/// takes finite, moderate ones.
fn canvas_pos(p: [f32; 2]) -> Pos2 {
    let coord = |c: f32| if c.is_finite() { c.clamp(-1e7, 1e7) } else { 0.0 };
    pos2(coord(p[0]), coord(p[1]))
}

fn bezier(a: Pos2, b: Pos2, c: Pos2, d: Pos2, t: f32) -> Pos2 {
    let u = 1.0 - t;
    let v = a.to_vec2() * (u * u * u)
        + b.to_vec2() * (3.0 * u * u * t)
        + c.to_vec2() * (3.0 * u * t * t)
        + d.to_vec2() * (t * t * t);
    v.to_pos2()
}

fn spec_of(graph: &Graph, id: &str) -> Option<&'static NodeSpec> {
    spec::find(&graph.nodes.get(id)?.kind)
}

struct Viewer<'a> {
    graph: &'a Graph,
    live: &'a Live,
    selection: &'a BTreeSet<String>,
    inspected: Option<&'a PortRef>,
    show_timings: bool,
    actions: Vec<Action>,
    pins: Rc<RefCell<PinRects>>,
    node_rects: &'a mut HashMap<String, Rect>,
    header_widths: &'a mut HashMap<String, f32>,
    specs: &'a HashMap<String, &'static NodeSpec>,
    /// Each node's state, computed once per frame.
    states: HashMap<String, NodeState>,
    search: &'a mut String,
    to_global: TSTransform,
    fit_to: Option<TSTransform>,
    insert_hint: Option<&'a [Pos2]>,
    pressed_node: Option<String>,
}

impl Viewer<'_> {
    fn spec(&self, id: &str) -> Option<&'static NodeSpec> {
        self.specs.get(id).copied()
    }

    fn state(&self, id: &str) -> &NodeState {
        self.states.get(id).unwrap_or(&NodeState::Idle)
    }

    fn out_ref(&self, snarl: &Snarl<String>, pin: OutPinId) -> Option<(PortRef, PortType)> {
        let id = snarl.get_node(pin.node)?;
        let p = self.spec(id)?.outputs.get(pin.output)?;
        Some((PortRef { node: id.clone(), port: p.name.into() }, p.ty))
    }

    fn in_ref(&self, snarl: &Snarl<String>, pin: InPinId) -> Option<(PortRef, PortType)> {
        let id = snarl.get_node(pin.node)?;
        let p = self.spec(id)?.inputs.get(pin.input)?;
        Some((PortRef { node: id.clone(), port: p.name.into() }, p.ty))
    }

    fn pin(&self, ty: PortType, key: (String, bool, usize), connected: bool) -> TypedPin {
        let color = port_color(ty);
        let info = PinInfo::default()
            .with_shape(if ty.viewable() { PinShape::Square } else { PinShape::Circle })
            .with_fill(if connected { color } else { color.gamma_multiply(0.55) })
            .with_stroke(Stroke::new(1.0, Color32::from_gray(20)))
            .with_wire_color(color);
        TypedPin { info, key, sink: self.pins.clone() }
    }

    /// A tooltip text for a port: type, doc, and its current value or state.
    fn port_tooltip(&self, port: &PortRef, input: bool) -> String {
        let Some(spec) = self.spec(&port.node) else { return String::new() };
        let p = if input { spec.input(&port.port) } else { spec.output(&port.port) };
        let Some((_, p)) = p else { return String::new() };
        let mut text =
            format!("{}: {}{}\n{}", p.name, p.ty, if input && p.required { " (required)" } else { "" }, p.doc);
        match self.live.summary(port, input) {
            Some(v) => text.push_str(&format!("\nvalue: {v}")),
            None => match self.state(&port.node) {
                NodeState::Pending(m) => text.push_str(&format!("\nresource: {m}")),
                NodeState::Failed(_) | NodeState::Blocked(_) => text.push_str("\nno value (the node has an error)"),
                NodeState::Idle if !input => text.push_str("\nno value (not needed by any output)"),
                _ if input => text.push_str("\nnot connected"),
                _ => {}
            },
        }
        if !input && p.ty.viewable() {
            text.push_str("\nclick to show in the viewport");
        }
        text
    }
}

impl SnarlViewer<String> for Viewer<'_> {
    fn title(&mut self, node: &String) -> String {
        node.clone()
    }

    fn draw_background(
        &mut self,
        background: Option<&BackgroundPattern>,
        viewport: &Rect,
        snarl_style: &SnarlStyle,
        style: &egui::Style,
        painter: &egui::Painter,
        _snarl: &Snarl<String>,
    ) {
        if let Some(background) = background {
            background.draw(viewport, snarl_style, style, painter);
        }
        if let Some(points) = self.insert_hint {
            painter.add(egui::Shape::line(points.to_vec(), Stroke::new(8.0, SELECT_COLOR.gamma_multiply(0.5))));
        }
    }

    fn current_transform(&mut self, to_global: &mut TSTransform, _snarl: &mut Snarl<String>) {
        if let Some(t) = self.fit_to.take() {
            *to_global = t;
        }
        self.to_global = *to_global;
    }

    fn node_frame(
        &mut self,
        default: egui::Frame,
        node: NodeId,
        _inputs: &[InPin],
        _outputs: &[OutPin],
        snarl: &Snarl<String>,
    ) -> egui::Frame {
        let Some(id) = snarl.get_node(node) else { return default };
        let mut frame = default;
        if self.selection.contains(id) {
            frame.stroke = Stroke::new(2.0, SELECT_COLOR);
        }
        match self.state(id) {
            NodeState::Failed(_) => frame.stroke = Stroke::new(2.0, ERROR_COLOR),
            NodeState::Pending(_) | NodeState::Blocked(_) if !self.selection.contains(id) => {
                frame.stroke = Stroke::new(1.5, PENDING_COLOR.gamma_multiply(0.7))
            }
            _ => {}
        }
        frame
    }

    fn header_frame(
        &mut self,
        default: egui::Frame,
        node: NodeId,
        _inputs: &[InPin],
        _outputs: &[OutPin],
        snarl: &Snarl<String>,
    ) -> egui::Frame {
        let Some(id) = snarl.get_node(node) else { return default };
        match self.state(id) {
            NodeState::Failed(_) => default.fill(Color32::from_rgb(120, 30, 30)),
            NodeState::Pending(_) => default.fill(Color32::from_rgb(110, 85, 20)),
            NodeState::Blocked(_) => default.fill(Color32::from_rgb(70, 60, 40)),
            _ => default,
        }
    }

    fn show_header(
        &mut self,
        node: NodeId,
        _inputs: &[InPin],
        _outputs: &[OutPin],
        ui: &mut Ui,
        snarl: &mut Snarl<String>,
    ) {
        let Some(id) = snarl.get_node(node).cloned() else { return };
        let kind = self.graph.nodes.get(&id).map(|n| n.kind.clone()).unwrap_or_default();
        // The header is already a left-to-right row.
        let a = ui.label(RichText::new(&id).strong());
        let b = ui.label(RichText::new(&kind).small().weak());
        // Snarl sizes a node by its pins and footer; remember the header's width so the
        // footer can make room for it (else a long title is clipped).
        let width = a.rect.width() + b.rect.width() + ui.spacing().item_spacing.x + ui.spacing().icon_width + 8.0;
        self.header_widths.insert(id, width);
        if let Some(spec) = spec::find(&kind) {
            b.on_hover_text(spec.doc);
        }
    }

    fn inputs(&mut self, node: &String) -> usize {
        self.spec(node).map_or(0, |s| s.inputs.len())
    }

    fn outputs(&mut self, node: &String) -> usize {
        self.spec(node).map_or(0, |s| s.outputs.len())
    }

    fn show_input(&mut self, pin: &InPin, ui: &mut Ui, snarl: &mut Snarl<String>) -> impl SnarlPin + 'static {
        let id = snarl.get_node(pin.id.node).cloned().unwrap_or_default();
        let (port, ty) =
            self.in_ref(snarl, pin.id).unwrap_or((PortRef { node: id.clone(), port: "?".into() }, PortType::Scalar));
        let required = self.spec(&id).and_then(|s| s.inputs.get(pin.id.input)).is_some_and(|p| p.required);
        let mut text = RichText::new(&port.port).small();
        if required && pin.remotes.is_empty() {
            text = text.color(ERROR_COLOR);
        }
        let r = ui.add(egui::Label::new(text).sense(Sense::hover()));
        if r.hovered() {
            r.on_hover_text(self.port_tooltip(&port, true));
        }
        self.pin(ty, (id, true, pin.id.input), !pin.remotes.is_empty())
    }

    fn show_output(&mut self, pin: &OutPin, ui: &mut Ui, snarl: &mut Snarl<String>) -> impl SnarlPin + 'static {
        let id = snarl.get_node(pin.id.node).cloned().unwrap_or_default();
        let (port, ty) =
            self.out_ref(snarl, pin.id).unwrap_or((PortRef { node: id.clone(), port: "?".into() }, PortType::Scalar));
        let texture = ty.viewable();
        let shown = self.inspected == Some(&port);
        let mut text = RichText::new(if shown { format!("👁 {}", port.port) } else { port.port.clone() }).small();
        if texture {
            text = text.underline();
        }
        let r = ui.add(egui::Label::new(text).sense(if texture { Sense::click() } else { Sense::hover() }));
        if texture && r.clicked() {
            self.actions.push(Action::Inspect(if shown { None } else { Some(port.clone()) }));
        }
        if r.hovered() {
            r.on_hover_text(self.port_tooltip(&port, false));
        }
        self.pin(ty, (id, false, pin.id.output), !pin.remotes.is_empty())
    }

    fn has_footer(&mut self, _node: &String) -> bool {
        // Always: the footer also keeps the node as wide as its header.
        true
    }

    fn show_footer(
        &mut self,
        node: NodeId,
        _inputs: &[InPin],
        _outputs: &[OutPin],
        ui: &mut Ui,
        snarl: &mut Snarl<String>,
    ) {
        let Some(id) = snarl.get_node(node).cloned() else { return };
        let min_width = self.header_widths.get(&id).copied().unwrap_or(0.0);
        ui.vertical(|ui| {
            ui.set_max_width(min_width.max(240.0));
            ui.set_min_width(min_width);
            match self.state(&id) {
                NodeState::Failed(m) => {
                    ui.add(egui::Label::new(RichText::new(format!("error: {m}")).small().color(ERROR_COLOR)).wrap());
                }
                NodeState::Pending(m) => {
                    ui.add(
                        egui::Label::new(RichText::new(format!("pending: {m}")).small().color(PENDING_COLOR)).wrap(),
                    );
                }
                NodeState::Blocked(m) => {
                    ui.add(egui::Label::new(RichText::new(m).small().color(PENDING_COLOR)).wrap());
                }
                _ => {}
            }
            // The node the worker runs now, and how far it is.
            if let Some(b) = self.live.busy().filter(|b| b.node.as_deref() == Some(id.as_str())) {
                ui.add(
                    egui::ProgressBar::new(b.fraction)
                        .desired_width(min_width.max(120.0))
                        .text(RichText::new(format!("running {:.0}%", b.fraction * 100.0)).small()),
                );
            }
            for w in self.live.warnings(&id) {
                ui.add(egui::Label::new(RichText::new(format!("warning: {w}")).small().color(PENDING_COLOR)).wrap());
            }
            if self.show_timings {
                let text = match self.live.timing(&id) {
                    Some((t, true)) => format!("{:.2} ms", t.as_secs_f64() * 1e3),
                    Some((t, false)) => format!("cached ({:.2} ms)", t.as_secs_f64() * 1e3),
                    None => "not run".into(),
                };
                ui.label(RichText::new(format!("⏱ {text}")).small().monospace());
            }
        });
    }

    fn final_node_rect(&mut self, node: NodeId, rect: Rect, ui: &mut Ui, snarl: &mut Snarl<String>) {
        let Some(id) = snarl.get_node(node).cloned() else { return };
        self.node_rects.insert(id.clone(), rect);
        let (pressed, pos) = ui.input(|i| (i.pointer.primary_pressed(), i.pointer.interact_pos()));
        // Only presses on the canvas itself: not on a menu or popup above it, not where the
        // node is clipped away under a side panel.
        let on_canvas = |pos: Pos2| ui.ctx().layer_id_at(pos).is_none_or(|l| l.order == egui::Order::Background);
        if pressed
            && let Some(pos) = pos
            && on_canvas(pos)
            && rect.contains(self.to_global.inverse() * pos)
            && ui.clip_rect().contains(self.to_global.inverse() * pos)
        {
            // Later nodes are drawn on top, so the last hit wins.
            self.pressed_node = Some(id);
        }
    }

    fn has_graph_menu(&mut self, _pos: Pos2, _snarl: &mut Snarl<String>) -> bool {
        true
    }

    fn show_graph_menu(&mut self, pos: Pos2, ui: &mut Ui, _snarl: &mut Snarl<String>) {
        ui.label(RichText::new("Add node").strong());
        if let Some((spec, _)) = node_menu(ui, self.search, None) {
            self.actions.push(Action::Add { kind: spec.kind, pos: [pos.x.round(), pos.y.round()] });
            self.search.clear();
            ui.close();
        }
    }

    fn has_dropped_wire_menu(&mut self, _src: AnyPins, _snarl: &mut Snarl<String>) -> bool {
        true
    }

    fn show_dropped_wire_menu(&mut self, pos: Pos2, ui: &mut Ui, src: AnyPins, snarl: &mut Snarl<String>) {
        let (port, ty, from_output) = match src {
            AnyPins::Out(pins) => match pins.first().and_then(|p| self.out_ref(snarl, *p)) {
                Some((port, ty)) => (port, ty, true),
                None => return,
            },
            AnyPins::In(pins) => match pins.first().and_then(|p| self.in_ref(snarl, *p)) {
                Some((port, ty)) => (port, ty, false),
                None => return,
            },
        };
        ui.label(RichText::new(format!("Add node for {port} ({ty})")).strong());
        if let Some((spec, new_port)) = node_menu(ui, self.search, Some((ty, from_output))) {
            self.actions.push(Action::AddConnected {
                kind: spec.kind,
                pos: [pos.x.round(), pos.y.round()],
                port,
                from_output,
                new_port,
            });
            self.search.clear();
            ui.close();
        }
    }

    fn has_node_menu(&mut self, _node: &String) -> bool {
        true
    }

    fn show_node_menu(
        &mut self,
        node: NodeId,
        _inputs: &[InPin],
        _outputs: &[OutPin],
        ui: &mut Ui,
        snarl: &mut Snarl<String>,
    ) {
        let Some(id) = snarl.get_node(node).cloned() else { return };
        if !self.selection.contains(&id) {
            self.actions.push(Action::SelectOnly(id.clone()));
        }
        if let Some(spec) = self.spec(&id) {
            for p in spec.outputs.iter().filter(|p| p.ty.viewable()) {
                if ui.button(format!("Show {}.{}", id, p.name)).clicked() {
                    self.actions.push(Action::Inspect(Some(PortRef { node: id.clone(), port: p.name.into() })));
                    ui.close();
                }
            }
        }
        for (label, action) in [("Duplicate", Action::Duplicate), ("Copy", Action::Copy), ("Delete", Action::Delete)] {
            if ui.button(label).clicked() {
                self.actions.push(action);
                ui.close();
            }
        }
    }

    fn connect(&mut self, from: &OutPin, to: &InPin, snarl: &mut Snarl<String>) {
        if let (Some((f, _)), Some((t, _))) = (self.out_ref(snarl, from.id), self.in_ref(snarl, to.id)) {
            self.actions.push(Action::Connect(f, t));
        }
    }

    fn disconnect(&mut self, from: &OutPin, to: &InPin, snarl: &mut Snarl<String>) {
        if let (Some((f, _)), Some((t, _))) = (self.out_ref(snarl, from.id), self.in_ref(snarl, to.id)) {
            self.actions.push(Action::RemoveLink(Link { from: f, to: t }));
        }
    }

    fn drop_outputs(&mut self, pin: &OutPin, snarl: &mut Snarl<String>) {
        if let Some((f, _)) = self.out_ref(snarl, pin.id) {
            self.actions.push(Action::DisconnectOutput(f));
        }
    }

    fn drop_inputs(&mut self, pin: &InPin, snarl: &mut Snarl<String>) {
        if let Some((t, _)) = self.in_ref(snarl, pin.id) {
            self.actions.push(Action::DisconnectInput(t));
        }
    }
}

/// The add-node menu: a search field and the registry by category. With `filter`, only
/// kinds with a port that fits a wire of that type (dropped from an output when `true`).
/// Returns the chosen kind and the port to connect.
pub fn node_menu(
    ui: &mut Ui,
    search: &mut String,
    filter: Option<(PortType, bool)>,
) -> Option<(&'static NodeSpec, &'static str)> {
    let field = ui.add(egui::TextEdit::singleline(search).hint_text("search nodes").desired_width(200.0));
    if search.is_empty() && !field.has_focus() && !ui.ctx().memory(|m| m.focused().is_some()) {
        field.request_focus();
    }
    let candidates: Vec<(&'static NodeSpec, &'static str)> = match filter {
        Some((ty, from_output)) => compatible_kinds(ty, from_output),
        None => spec::all().iter().map(|s| (*s, "")).collect(),
    };
    let query = search.trim().to_lowercase();
    let mut picked = None;
    if !query.is_empty() {
        let hits: Vec<_> = candidates
            .iter()
            .filter(|(s, _)| {
                s.kind.to_lowercase().contains(&query)
                    || s.doc.to_lowercase().contains(&query)
                    || s.category.to_string().to_lowercase().contains(&query)
            })
            .collect();
        if hits.is_empty() {
            ui.weak("no node kind matches");
        }
        for (s, port) in &hits {
            if ui.button(s.kind).on_hover_text(s.doc).clicked() {
                picked = Some((*s, *port));
            }
        }
        if field.lost_focus()
            && ui.input(|i| i.key_pressed(egui::Key::Enter))
            && let Some((s, port)) = hits.first()
        {
            picked = Some((*s, *port));
        }
    } else {
        for cat in Category::ALL {
            let in_cat: Vec<_> = candidates.iter().filter(|(s, _)| s.category == cat).collect();
            if in_cat.is_empty() {
                continue;
            }
            ui.menu_button(cat.to_string(), |ui| {
                for (s, port) in in_cat {
                    if ui.button(s.kind).on_hover_text(s.doc).clicked() {
                        picked = Some((*s, *port));
                        ui.close();
                    }
                }
            });
        }
    }
    picked
}
