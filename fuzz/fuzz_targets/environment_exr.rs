//! Environment maps in OpenEXR: any bytes are a map or an
//! error, decoded only after the size the header declares fits the memory given (512 MiB
//! here), and an accepted map holds finite, non-negative radiance.
#![no_main]

use canopy_render::background::{decode_environment_within, MAX_ENVIRONMENT_PIXELS};
use glam::Mat3;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let available = Some(512 << 20);
    if let Ok(map) = decode_environment_within("fuzz.exr", data, Mat3::IDENTITY, 1.0, available) {
        let (w, h) = map.size();
        assert!(w * h > 0 && (w * h) as u64 <= MAX_ENVIRONMENT_PIXELS);
        assert!(map.pixels().iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
    }
});
