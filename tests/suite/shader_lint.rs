//! Static checks of the WGSL sources through naga's IR (no GPU).
//!
//! lavapipe (Mesa 22.3) specializes a shader to the values of the uniforms that a branch or a
//! loop's bound depends on alone, and compiles it again on every draw that binds them
//! ("uniform inlining"): with a cold shader cache IblShading took 3.8 s per frame instead of
//! 0.3 s. Such switches are `override` constants (FullscreenPass::draw_specialized, a draw
//! kind's PipelineKey constants). This test finds conditions that read uniforms and nothing
//! that varies per invocation.

use naga::{AddressSpace, Block, Expression, Function, Handle, Module, Statement};

/// Shaders whose uniform-only switches stay, each with why. lavapipe inlines only shaders of more
/// than about 100 values, and keeps inlining only where that at least halves the shader; these
/// were measured not to recompile per draw (every graph rendered with `MESA_SHADER_CACHE_DISABLE`
/// against a warm cache, docs/ibl.md), or run once per edit.
const ALLOWED: &[(&str, &str)] = &[
    ("tonemap.wgsl", "one small pass per frame: below lavapipe's size threshold"),
    ("matrix_filter.wgsl", "runs when a matrix texture is rebuilt; measured equal cold and warm"),
    ("tessellate.wgsl", "compute; inlining does not halve it, measured equal cold and warm (fig5_13..15)"),
    ("pem_phong.wgsl", "PEM builds: once per probe or kernel change"),
    ("vsm_blur.wgsl", "inlining the radius unrolls the loop (no halving); the atlas measured equal cold and warm"),
    ("ssr.wgsl", "measured recompiling (graphs/ssr.ron): to be made constants"),
];

/// What a condition reads.
#[derive(Clone, Copy, Default)]
struct Reads {
    /// A uniform block.
    uniform: bool,
    /// A function-local variable (a loop counter).
    local: bool,
    /// Anything that varies per invocation.
    varying: bool,
}

fn join(a: Reads, b: Reads) -> Reads {
    Reads { uniform: a.uniform || b.uniform, local: a.local || b.local, varying: a.varying || b.varying }
}

const FIXED: Reads = Reads { uniform: false, local: false, varying: false };
const VARYING: Reads = Reads { uniform: false, local: false, varying: true };

fn reads(module: &Module, f: &Function, e: Handle<Expression>) -> Reads {
    use Expression as E;
    let s = |h| reads(module, f, h);
    match &f.expressions[e] {
        E::Literal(_) | E::Constant(_) | E::Override(_) | E::ZeroValue(_) => FIXED,
        E::GlobalVariable(g) => {
            if module.global_variables[*g].space == AddressSpace::Uniform {
                Reads { uniform: true, ..FIXED }
            } else {
                VARYING
            }
        }
        E::LocalVariable(_) => Reads { local: true, ..FIXED },
        E::Load { pointer } => s(*pointer),
        E::AccessIndex { base, .. } => s(*base),
        E::Access { base, index } => join(s(*base), s(*index)),
        E::Splat { value, .. } => s(*value),
        E::Swizzle { vector, .. } => s(*vector),
        E::Compose { components, .. } => components.iter().fold(FIXED, |a, c| join(a, s(*c))),
        E::Unary { expr, .. } | E::As { expr, .. } => s(*expr),
        E::Binary { left, right, .. } => join(s(*left), s(*right)),
        E::Select { condition, accept, reject } => join(join(s(*condition), s(*accept)), s(*reject)),
        E::Relational { argument, .. } => s(*argument),
        E::Math { arg, arg1, arg2, arg3, .. } => {
            [Some(*arg), *arg1, *arg2, *arg3].into_iter().flatten().fold(FIXED, |a, h| join(a, s(h)))
        }
        _ => VARYING,
    }
}

/// Conditions in `block` that read a uniform and nothing varying: an `if` on uniforms alone,
/// or a loop's exit test against a uniform bound (`for (var k = 0u; k < n; k++)`).
fn find(module: &Module, f: &Function, block: &Block, in_loop_head: bool, found: &mut Vec<String>) {
    let mut first = in_loop_head;
    for st in block.iter() {
        // A `for` loop's exit test is the first statement of its body after the evaluations.
        let loop_head = first && !matches!(st, Statement::Emit(_));
        if loop_head || !matches!(st, Statement::Emit(_)) {
            first = false;
        }
        match st {
            Statement::If { condition, accept, reject } => {
                let r = reads(module, f, *condition);
                let loop_exit = loop_head && r.local;
                if r.uniform && !r.varying && (!r.local || loop_exit) {
                    let name = f.name.as_deref().unwrap_or("?");
                    let what = if loop_exit { "a loop bounded by a uniform" } else { "a branch on uniforms alone" };
                    found.push(format!("{name}: {what}"));
                }
                find(module, f, accept, false, found);
                find(module, f, reject, false, found);
            }
            Statement::Loop { body, continuing, .. } => {
                find(module, f, body, true, found);
                find(module, f, continuing, false, found);
            }
            Statement::Block(b) => find(module, f, b, false, found),
            Statement::Switch { cases, .. } => {
                for c in cases {
                    find(module, f, &c.body, false, found);
                }
            }
            _ => {}
        }
    }
}

fn uniform_switches(name: &str) -> Vec<String> {
    let text = werkstatt::gpu::shaders::source(name).unwrap();
    let module = naga::front::wgsl::parse_str(&text).unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&text)));
    let mut found = Vec::new();
    for (_, f) in module.functions.iter() {
        find(&module, f, &f.body, false, &mut found);
    }
    for ep in &module.entry_points {
        find(&module, &ep.function, &ep.function.body, false, &mut found);
    }
    found.sort();
    found.dedup();
    found
}

#[test]
fn no_shader_branches_on_uniforms_alone() {
    let mut offenders = Vec::new();
    // Pieces that passes include are checked as part of those passes.
    let included: Vec<String> = werkstatt::gpu::shaders::paths()
        .flat_map(|p| {
            std::fs::read_to_string(crate::common::root().join("shaders").join(p))
                .unwrap()
                .lines()
                .map(str::to_owned)
                .collect::<Vec<_>>()
        })
        .filter_map(|l| l.trim().strip_prefix("// #include ").map(|i| i.trim().trim_matches('"').to_owned()))
        .collect();
    for name in werkstatt::gpu::shaders::names() {
        if included.iter().any(|i| i == name) {
            continue;
        }
        for f in uniform_switches(name) {
            if !ALLOWED.iter().any(|&(s, _why)| s == name) {
                offenders.push(format!("{name} {f}"));
            }
        }
    }
    assert!(
        offenders.is_empty(),
        "switches read from uniform blocks (make them override constants, see this file's header):\n{}",
        offenders.join("\n")
    );
}

/// The check finds what it is for: IblShading's switches as they were.
#[test]
fn the_uniform_branch_check_finds_branches_and_loop_bounds() {
    let shader = "
        struct U { n: f32, flag: f32, scale: f32 };
        @group(0) @binding(0) var<uniform> u: U;
        @group(0) @binding(1) var t: texture_2d<f32>;
        override FLAG: bool = false;
        fn f(x: f32) -> f32 { if x > u.scale { return 1.0; } return 0.0; }
        @fragment fn fs(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
            var s = f(p.x);
            if u.flag > 0.5 { s += 1.0; }
            if FLAG { s += 2.0; }
            if textureLoad(t, vec2<i32>(p.xy), 0).x > u.scale { s += 3.0; }
            let n = u32(u.n);
            for (var k = 0u; k < n; k++) { s += 1.0; }
            for (var k = 0u; k < 4u; k++) { s += 1.0; }
            return vec4<f32>(s);
        }";
    let module = naga::front::wgsl::parse_str(shader).unwrap();
    let mut found = Vec::new();
    for ep in &module.entry_points {
        find(&module, &ep.function, &ep.function.body, false, &mut found);
    }
    for (_, f) in module.functions.iter() {
        find(&module, f, &f.body, false, &mut found);
    }
    assert_eq!(found, ["fs: a branch on uniforms alone", "fs: a loop bounded by a uniform"]);
}
