//! `surgbench`: the command line ([`surgbench::cli`]).

use std::process::ExitCode;
use surgbench::cli::{self, Launcher};

fn main() -> ExitCode {
    match std::env::current_exe() {
        Ok(exe) => ExitCode::from(cli::main(std::env::args_os(), Launcher { exe, args: Vec::new() })),
        Err(e) => {
            eprintln!("error: cannot find own executable: {e}");
            ExitCode::from(1)
        }
    }
}
