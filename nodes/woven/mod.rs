pub mod woven_cloth;
