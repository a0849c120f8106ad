//! The checkpoint reader: any bytes are a whole checkpoint or an error; what it accepts
//! writes back to the same bytes.
#![no_main]

use canopy_render::checkpoint::Checkpoint;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(checkpoint) = Checkpoint::from_bytes(data) {
        assert_eq!(checkpoint.to_bytes(), data);
    }
});
