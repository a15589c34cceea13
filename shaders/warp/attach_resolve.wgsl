// Point attachments look up one frame per instance (eq. 4: f_uv is constant), so it is
// looked up once here instead of once per vertex. The frame is written into the instance's
// M_tex and curve slots, which point attachments do not need afterwards; warp.wgsl reads it
// back in mode 5.

// #include "warp.wgsl"

@group(0) @binding(0) var<storage, read> instances: array<Instance>;
@group(0) @binding(1) var<storage, read_write> resolved: array<Instance>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x + id.y * 65535u * 64u;
    if i >= arrayLength(&instances) {
        return;
    }
    var inst = instances[i];
    let uv = vec2<f32>(inst.m_tex0.z, inst.m_tex1.z);
    let f = lookup_frame(uv);
    inst.m_tex0 = vec4<f32>(f.tu, f.p.x);
    inst.m_tex1 = vec4<f32>(f.n, f.p.y);
    inst.curve01 = vec4<f32>(f.tv, f.p.z);
    inst.curve23 = vec4<f32>(select(0.0, 1.0, f.valid), 0.0, 0.0, 0.0);
    resolved[i] = inst;
}
