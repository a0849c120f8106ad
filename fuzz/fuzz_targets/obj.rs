//! The OBJ reader: any bytes are a valid mesh or an error.
#![no_main]

use canopy_render::mesh::{parse_mesh, MeshFormat};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(mesh) = parse_mesh(data, MeshFormat::Obj) {
        assert!(mesh.validate().is_ok());
    }
});
