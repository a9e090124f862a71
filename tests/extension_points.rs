//! The extension points of the workspace, exercised through the examples
//! a third party would write (`crates/fmaps/examples/custom_*.rs`, public
//! API only): each passes the exported conformance check and runs through
//! `fmaps::match_shapes` (their `main` returns an error otherwise).

#[path = "../crates/fmaps/examples/custom_backend.rs"]
mod custom_backend;
#[path = "../crates/fmaps/examples/custom_refiner.rs"]
mod custom_refiner;

#[test]
fn a_custom_eigensolver_backend_plugs_in() {
    custom_backend::main().unwrap();
}

#[test]
fn a_custom_refiner_plugs_in() {
    custom_refiner::main().unwrap();
}
