//! surgbench command-line interface.
fn main() {}
