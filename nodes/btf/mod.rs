//! BTF cloth nodes (src/btf/): the compressed BTF and its deferred shading.

pub mod btf_resource;
pub mod btf_shading;
pub mod btf_slot;
