//! The checkpoint reader: any bytes are a whole checkpoint or an error; what it accepts
//! (of any version it reads) writes back, in the current version, to a checkpoint that
//! reads as the same.
#![no_main]

use canopy_render::checkpoint::Checkpoint;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(checkpoint) = Checkpoint::from_bytes(data) {
        let again = Checkpoint::from_bytes(&checkpoint.to_bytes()).expect("its own bytes read");
        assert_eq!(again, checkpoint);
    }
});
