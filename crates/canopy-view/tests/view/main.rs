//! canopy-view's integration tests: the viewer's protocol over real sockets.
//!
//! One binary for all of them (one link instead of one per file); each file is a module.

mod protocol;
