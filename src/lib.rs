//! The `surgbench` command line as a library: the binary (`src/main.rs`)
//! and the Python bindings (`python -m surgbench`, the `python/` crate)
//! run the same [`cli::main`].

pub mod cli;
